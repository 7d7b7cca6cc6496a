#pragma once
// Process-wide allocator settings for a streaming server (glibc malloc; a no-op elsewhere).
//
// A server decodes a LiDAR sweep of ~0.5 MB several times over (protobuf, message, cloud) ten
// times a second per session. glibc serves such blocks with mmap() and returns them with
// munmap(), and trims freed heap tops: every sweep then faults its pages in anew (on the 2-core
// VM, 20 sessions: 310k page faults in 25 s, a tenth of the server's CPU in the kernel). This
// keeps blocks up to 32 MB on the heap and trims only above 256 MB of free top, so the buffers
// are reused. Cost: freed memory stays with the process (peak RSS +25 % in the load bench).
//
// Call once at start, before threads allocate (hanzo-fusion serve does; embedders choose).

namespace hanzo::fusion::service {

/// Returns false when the C library refused a setting (or is not glibc).
bool keep_large_buffers_on_heap();

}  // namespace hanzo::fusion::service
