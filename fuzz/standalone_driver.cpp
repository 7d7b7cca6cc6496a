// Runs a fuzz target without libFuzzer (GCC builds, ctest): every seed file given, then
// `--iterations N` inputs made by mutating the seeds (bit flips, byte changes, insertions,
// deletions, truncation, splicing two seeds) with a fixed random seed, so a failure
// reproduces. `make fuzz` builds the same targets with clang's libFuzzer instead.
//
//   fuzz_TARGET [--iterations N] [--seed S] SEED_FILE_OR_DIR...

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

std::vector<uint8_t> read_file(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(file), {}};
}

std::vector<uint8_t> mutate(std::vector<uint8_t> input, const std::vector<std::vector<uint8_t>>& seeds, std::mt19937_64& random) {
  const int mutations = 1 + static_cast<int>(random() % 4);
  for (int m = 0; m < mutations; ++m) {
    const size_t position = input.empty() ? 0 : random() % input.size();
    switch (random() % 6) {
      case 0: if (!input.empty()) input[position] ^= static_cast<uint8_t>(1u << (random() % 8)); break;
      case 1: if (!input.empty()) input[position] = static_cast<uint8_t>(random()); break;
      case 2: input.insert(input.begin() + static_cast<long>(position), static_cast<uint8_t>(random())); break;
      case 3: if (!input.empty()) input.erase(input.begin() + static_cast<long>(position)); break;
      case 4: input.resize(position); break;
      default: {
        const std::vector<uint8_t>& other = seeds[random() % seeds.size()];
        if (other.empty()) break;
        const size_t from = random() % other.size();
        input.insert(input.begin() + static_cast<long>(position), other.begin() + static_cast<long>(from), other.end());
      }
    }
  }
  return input;
}

}  // namespace

int main(int argc, char** argv) {
  long iterations = 0;
  uint64_t seed = 1;
  std::vector<std::vector<uint8_t>> seeds;
  for (int i = 1; i < argc; ++i) {
    const std::string argument = argv[i];
    if (argument == "--iterations" && i + 1 < argc) {
      iterations = std::atol(argv[++i]);
    } else if (argument == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (std::filesystem::is_directory(argument)) {
      for (const auto& entry : std::filesystem::directory_iterator(argument)) seeds.push_back(read_file(entry.path()));
    } else {
      seeds.push_back(read_file(argument));
    }
  }
  if (seeds.empty()) seeds.emplace_back();
  for (const auto& input : seeds) LLVMFuzzerTestOneInput(input.data(), input.size());
  std::mt19937_64 random(seed);
  for (long i = 0; i < iterations; ++i) {
    const std::vector<uint8_t> input = mutate(seeds[random() % seeds.size()], seeds, random);
    LLVMFuzzerTestOneInput(input.data(), input.size());
  }
  std::printf("%zu seeds and %ld mutated inputs ran without a crash\n", seeds.size(), iterations);
  return 0;
}
