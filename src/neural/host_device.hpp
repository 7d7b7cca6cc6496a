#pragma once
// HANZO_HD marks functions compiled for both the CPU and, under nvcc, CUDA kernels.

#if defined(__CUDACC__)
#define HANZO_HD __host__ __device__ __forceinline__
#else
#define HANZO_HD inline
#endif
