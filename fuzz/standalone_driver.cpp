// Runs a fuzz target without libFuzzer (GCC builds, ctest): every seed file given, then
// `--iterations N` inputs made by mutating the seeds (bit flips, byte changes, insertions,
// deletions, truncation, splicing two seeds) with a fixed random seed, so a failure
// reproduces. `make fuzz` builds the same targets with clang's libFuzzer instead. An input that
// crashes the target (a signal, an uncaught exception) is written to crash-<target>.bin in the
// current folder: rerun it with fuzz_TARGET crash-<target>.bin.
//
//   fuzz_TARGET [--iterations N] [--seed S] SEED_FILE_OR_DIR...

#include <fcntl.h>
#include <unistd.h>

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

const std::vector<uint8_t>* current_input = nullptr;
char crash_path[256] = "crash.bin";

// Saves the input being run, then lets the signal do what it does.
void save_crashing_input(int signal_number) {
  if (current_input != nullptr) {
    const int fd = ::open(crash_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      (void)!::write(fd, current_input->data(), current_input->size());
      ::close(fd);
      (void)!::write(2, "crashing input saved to ", 24);
      (void)!::write(2, crash_path, std::strlen(crash_path));
      (void)!::write(2, "\n", 1);
    }
  }
  std::signal(signal_number, SIG_DFL);
  std::raise(signal_number);
}

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
  std::snprintf(crash_path, sizeof(crash_path), "crash-%s.bin", std::filesystem::path(argv[0]).filename().c_str());
  for (const int signal_number : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL}) std::signal(signal_number, save_crashing_input);
  for (const auto& input : seeds) {
    current_input = &input;
    LLVMFuzzerTestOneInput(input.data(), input.size());
  }
  std::mt19937_64 random(seed);
  for (long i = 0; i < iterations; ++i) {
    const std::vector<uint8_t> input = mutate(seeds[random() % seeds.size()], seeds, random);
    current_input = &input;
    LLVMFuzzerTestOneInput(input.data(), input.size());
  }
  current_input = nullptr;
  std::printf("%zu seeds and %ld mutated inputs ran without a crash\n", seeds.size(), iterations);
  return 0;
}
