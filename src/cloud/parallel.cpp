#include "hanzo/fusion/cloud/parallel.hpp"

#include <algorithm>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include <tbb/blocked_range.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "hanzo/fusion/core/thread_sanitizer.hpp"

namespace hanzo::fusion::cloud {
namespace {

constexpr size_t kMinChunkSize = 512;  // items; smaller chunks cost more in scheduling than they save
// At most this many chunks, whatever the thread count: the partition (and so the rounding of
// sums combined per chunk) is the same on every machine and thread count.
constexpr size_t kMaxChunks = 64;

// One arena per thread count, created on first use (an arena costs tens of microseconds to
// create, more than a small registration iteration).
tbb::task_arena& arena_for(int threads) {
  static std::mutex mutex;
  static std::map<int, std::unique_ptr<tbb::task_arena>> arenas;
  std::lock_guard<std::mutex> lock(mutex);
  auto& arena = arenas[threads];
  if (!arena) arena = std::make_unique<tbb::task_arena>(threads);
  return *arena;
}

}  // namespace

int thread_count(int num_threads) {
  if (kUnderThreadSanitizer) return 1;  // core/thread_sanitizer.hpp
  if (num_threads > 0) return num_threads;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

size_t chunk_count(size_t count) { return std::clamp<size_t>(count / kMinChunkSize, 1, kMaxChunks); }

void parallel_chunks(size_t count, int num_threads,
                     const std::function<void(size_t chunk, size_t begin, size_t end)>& body) {
  const size_t chunks = chunk_count(count);
  const auto run_chunk = [&](size_t chunk) {
    const size_t begin = count * chunk / chunks;
    const size_t end = count * (chunk + 1) / chunks;
    body(chunk, begin, end);
  };
  if (chunks == 1 || thread_count(num_threads) == 1) {
    for (size_t chunk = 0; chunk < chunks; ++chunk) run_chunk(chunk);
    return;
  }
  arena_for(thread_count(num_threads)).execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, chunks, 1), [&](const tbb::blocked_range<size_t>& range) {
      for (size_t chunk = range.begin(); chunk != range.end(); ++chunk) run_chunk(chunk);
    });
  });
}

void parallel_invoke(int num_threads, const std::function<void()>& first, const std::function<void()>& second) {
  const int threads = thread_count(num_threads);
  if (threads == 1) {
    first();
    second();
    return;
  }
  arena_for(threads).execute([&] { tbb::parallel_invoke(first, second); });
}

}  // namespace hanzo::fusion::cloud
