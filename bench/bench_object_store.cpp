// Object storage: puts and gets of whole objects on the local disk and on S3 (s3rver on
// 127.0.0.1, started here), against the peer on the machine: libcurl's own Signature Version 4
// signer (CURLOPT_AWS_SIGV4) sending the same requests. Then the map store: saving and loading
// a warehouse-sized map, plain and encrypted, and listing a map's versions from a fresh store on
// S3 (ranged reads of each version's first chunk). Run from the repository root (`make bench`).
#include <curl/curl.h>

#include <filesystem>
#include <fstream>
#include <random>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include "hanzo/fusion/maps/map_store.hpp"
#include "hanzo/fusion/object_store/object_store.hpp"
#include "support/local_s3_server.hpp"

namespace {

using namespace hanzo::fusion;
namespace fs = std::filesystem;

const fs::path kScratch = fs::temp_directory_path() / "hanzo_bench_object_store";

testing::LocalS3Server& s3_server() {
  static testing::LocalS3Server server(kScratch / "s3", "bench");
  return server;
}

std::string random_bytes(std::size_t size) {
  std::mt19937_64 random(7);
  std::string bytes(size, '\0');
  for (std::size_t i = 0; i + 8 <= size; i += 8) {
    const uint64_t value = random();
    std::memcpy(bytes.data() + i, &value, 8);
  }
  return bytes;
}

std::shared_ptr<object_store::ObjectStore> store_for(int backend) {
  if (backend == 0) return std::move(object_store::open_local_object_store((kScratch / "local").string()).value());
  return std::move(object_store::open_s3_object_store(s3_server().config("objects")).value());
}

void BM_Put(benchmark::State& state) {
  auto store = store_for(static_cast<int>(state.range(0)));
  const std::string bytes = random_bytes(static_cast<std::size_t>(state.range(1)) << 20);
  for (auto _ : state) {
    if (!store->put("bench/object.bin", bytes)) state.SkipWithError("put failed");
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
  state.SetLabel(state.range(0) == 0 ? "local disk" : "S3 (s3rver)");
}
BENCHMARK(BM_Put)->ArgsProduct({{0, 1}, {1, 16}})->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_Get(benchmark::State& state) {
  auto store = store_for(static_cast<int>(state.range(0)));
  const std::string bytes = random_bytes(static_cast<std::size_t>(state.range(1)) << 20);
  if (!store->put("bench/object.bin", bytes)) state.SkipWithError("put failed");
  for (auto _ : state) {
    auto got = store->get("bench/object.bin");
    if (!got || got->size() != bytes.size()) state.SkipWithError("get failed");
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
  state.SetLabel(state.range(0) == 0 ? "local disk" : "S3 (s3rver)");
}
BENCHMARK(BM_Get)->ArgsProduct({{0, 1}, {1, 16}})->Unit(benchmark::kMillisecond)->UseRealTime();

// A 96 MiB recording uploaded from its file: 6 parts of 16 MiB on S3.
void BM_PutLargeFile(benchmark::State& state) {
  auto store = store_for(static_cast<int>(state.range(0)));
  const fs::path file = kScratch / "recording.mcap";
  const std::string bytes = random_bytes(std::size_t{96} << 20);
  std::ofstream(file, std::ios::binary) << bytes;
  for (auto _ : state) {
    if (!store->put_file("bench/recording.mcap", file.string())) state.SkipWithError("put_file failed");
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
  state.SetLabel(state.range(0) == 0 ? "local disk" : "S3 multipart (s3rver)");
}
BENCHMARK(BM_PutLargeFile)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// The peer: the same PUT / GET with libcurl signing it (CURLOPT_AWS_SIGV4, UNSIGNED-PAYLOAD:
// no hash of the body, which our client computes).
std::size_t discard(char*, std::size_t size, std::size_t count, void* total) {
  *static_cast<std::size_t*>(total) += size * count;
  return size * count;
}

void BM_Peer_LibcurlSigV4(benchmark::State& state) {
  const bool put = state.range(0) == 0;
  const std::string bytes = random_bytes(static_cast<std::size_t>(state.range(1)) << 20);
  auto store = store_for(1);
  if (!store->put("bench/object.bin", bytes)) state.SkipWithError("put failed");
  const std::string url = fmt::format("{}/bench/objects/bench/object.bin", s3_server().endpoint());
  for (auto _ : state) {
    CURL* curl = curl_easy_init();
    std::size_t received = 0;
    curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
    curl_easy_setopt(curl, CURLOPT_AWS_SIGV4, "aws:amz:us-east-1:s3");
    curl_easy_setopt(curl, CURLOPT_USERPWD, "S3RVER:S3RVER");
    // libcurl 7.88 does not send the payload hash S3 requires: the peer sends it unsigned.
    curl_slist* headers = curl_slist_append(nullptr, "x-amz-content-sha256: UNSIGNED-PAYLOAD");
    curl_easy_setopt(curl, CURLOPT_HTTPHEADER, headers);
    curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, discard);
    curl_easy_setopt(curl, CURLOPT_WRITEDATA, &received);
    if (put) {
      curl_easy_setopt(curl, CURLOPT_CUSTOMREQUEST, "PUT");
      curl_easy_setopt(curl, CURLOPT_POSTFIELDS, bytes.data());
      curl_easy_setopt(curl, CURLOPT_POSTFIELDSIZE_LARGE, static_cast<curl_off_t>(bytes.size()));
    }
    long status = 0;
    if (curl_easy_perform(curl) != CURLE_OK) state.SkipWithError("libcurl request failed");
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
    if (status != 200 || (!put && received != bytes.size())) state.SkipWithError("libcurl request refused");
    curl_easy_cleanup(curl);
    curl_slist_free_all(headers);
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
  state.SetLabel(put ? "PUT, S3 (s3rver)" : "GET, S3 (s3rver)");
}
BENCHMARK(BM_Peer_LibcurlSigV4)->ArgsProduct({{0, 1}, {1, 16}})->Unit(benchmark::kMillisecond)->UseRealTime();

msgs::FusionMap warehouse_map() {
  msgs::FusionMap map;
  map.map_id = "warehouse";
  msgs::PointLayer points;
  std::mt19937 random(3);
  std::uniform_real_distribution<float> coordinate(0.0f, 40.0f);
  for (int i = 0; i < 300'000; ++i) points.points.emplace_back(coordinate(random), coordinate(random), coordinate(random) * 0.15f);
  map.points = points;
  return map;
}

// Save then load one map version: plain (range 0) or encrypted (1), on the local disk.
void BM_MapStoreSaveLoad(benchmark::State& state) {
  const bool encrypted = state.range(0) == 1;
  maps::MapStoreConfig config;
  if (encrypted) config.encryption_key = crypto::EncryptionKey::generate();
  fs::remove_all(kScratch / "maps");
  maps::MapStore store = std::move(maps::MapStore::open((kScratch / "maps").string(), config).value());
  const msgs::FusionMap map = warehouse_map();
  uint64_t bytes = 0;
  for (auto _ : state) {
    auto saved = store.save(map);
    if (!saved) state.SkipWithError(saved.error().message.c_str());
    bytes = saved->file_bytes;
    if (!store.load("warehouse", saved->version)) state.SkipWithError("load failed");
  }
  state.counters["file_MB"] = static_cast<double>(bytes) / 1e6;
  state.SetLabel(encrypted ? "encrypted (XChaCha20-Poly1305)" : "plain");
}
BENCHMARK(BM_MapStoreSaveLoad)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// Listing 20 encrypted versions from a fresh store on S3 (a restarted server's first listing).
void BM_MapStoreListVersionsS3(benchmark::State& state) {
  maps::MapStoreConfig config;
  config.encryption_key = crypto::EncryptionKey::generate();
  std::shared_ptr<object_store::ObjectStore> objects = store_for(1);
  if (!objects->remove_all("maps/")) state.SkipWithError("cannot clear the bucket");
  maps::MapStore writer(objects, "maps/", config);
  const msgs::FusionMap map = warehouse_map();
  for (int i = 0; i < 20; ++i) {
    if (!writer.save(map)) state.SkipWithError("save failed");
  }
  for (auto _ : state) {
    maps::MapStore fresh(objects, "maps/", config);
    auto versions = fresh.versions("warehouse");
    if (!versions || versions->size() != 20) state.SkipWithError("listing failed");
  }
  state.SetLabel("20 versions, encrypted, S3 (s3rver)");
}
BENCHMARK(BM_MapStoreListVersionsS3)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  fs::remove_all(kScratch);
  fs::create_directories(kScratch);
  if (!s3_server().error().empty()) {
    fmt::print(stderr, "bench_object_store: {}\n", s3_server().error());
    return 1;
  }
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  fs::remove_all(kScratch);
  return 0;
}
