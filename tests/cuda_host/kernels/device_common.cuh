/* tests/cuda_host/kernels/device_common.cuh -- host stand-in for spherevm/device_common.cuh, found
 * first on the include path when tests/cuda_host/kernels.cpp compiles the force kernels (.cu) for
 * the host. A kernel runs there one thread per call (h_set_thread picks the thread), so the thread
 * index is one block of one thread and the per-replica reduction is a plain sum.
 */
#pragma once

struct host_index { unsigned int x; };
inline host_index blockIdx = {0}, blockDim = {1}, threadIdx = {0};

inline void segmented_block_add(double value, int segment, double* out)
{
    if (segment >= 0) out[segment] += value;
}
