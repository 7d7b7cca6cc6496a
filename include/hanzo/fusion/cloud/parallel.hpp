#pragma once
// The parallel backend of the point-cloud algorithms (TBB). An algorithm splits its points
// into chunks, processes the chunks on up to `num_threads` threads and combines per-chunk
// partial results in chunk order, so results do not depend on thread scheduling.
//
// num_threads: 1 runs on the calling thread (no TBB involved); <= 0 uses every hardware thread.

#include <cstddef>
#include <functional>

namespace hanzo::fusion::cloud {

/// The threads `num_threads` stands for: itself when > 0, else every hardware thread.
int thread_count(int num_threads);

/// Number of chunks parallel_chunks() splits `count` items into (1 up to 64, at least 512 items
/// a chunk where there are enough); the same for every thread count.
size_t chunk_count(size_t count);

/// Calls body(chunk, begin, end) for chunk = 0 .. chunk_count(count, num_threads) - 1, the
/// ranges [begin, end) covering 0 .. count - 1 in order, concurrently on up to num_threads
/// threads. Returns when every chunk is done.
void parallel_chunks(size_t count, int num_threads,
                     const std::function<void(size_t chunk, size_t begin, size_t end)>& body);

/// parallel_chunks without the chunk index, for loops that write only per-item outputs.
inline void parallel_for(size_t count, int num_threads, const std::function<void(size_t begin, size_t end)>& body) {
  parallel_chunks(count, num_threads, [&body](size_t, size_t begin, size_t end) { body(begin, end); });
}

/// Runs first() and second() concurrently on up to num_threads threads (one after the other on
/// the calling thread when num_threads is 1); parallel loops inside them share those threads.
void parallel_invoke(int num_threads, const std::function<void()>& first, const std::function<void()>& second);

}  // namespace hanzo::fusion::cloud
