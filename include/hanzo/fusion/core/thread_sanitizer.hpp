#pragma once
// kUnderThreadSanitizer: true in a build with -fsanitize=thread. ThreadSanitizer cannot see the
// synchronization inside prebuilt, uninstrumented libraries (oneTBB's task scheduler), so it
// reports every TBB-parallel loop as a race; under it the TBB loops run serially (same results:
// the partitions do not depend on the thread count) and its reports are about this project's own
// threads.

namespace hanzo::fusion {

#if defined(__SANITIZE_THREAD__)
inline constexpr bool kUnderThreadSanitizer = true;
#else
inline constexpr bool kUnderThreadSanitizer = false;
#endif

}  // namespace hanzo::fusion
