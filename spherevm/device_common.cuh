// Reductions shared by spherevm's kernels: per-replica (segmented) sums and maxima.
#pragma once

// Add `value` into out[segment]. Threads of a block usually share one segment (replicas are
// contiguous ranges): then the block reduces in shared memory and issues one atomic; otherwise
// every thread adds its own value. Every thread of the block must call it (it synchronises);
// threads without work pass value 0 and any valid segment, or segment -1 to skip.
__device__ void segmented_block_add(double value, int segment, double* out) {
    __shared__ double partial[32];
    __shared__ int first_segment;
    __shared__ int uniform;
    if (threadIdx.x == 0) { first_segment = -2; uniform = 1; }
    __syncthreads();
    if (segment >= 0) atomicCAS(&first_segment, -2, segment);
    __syncthreads();
    if (segment >= 0 && segment != first_segment) uniform = 0;
    __syncthreads();
    if (!uniform) {
        if (segment >= 0 && value != 0.0) atomicAdd(out + segment, value);
        return;
    }
    double v = segment >= 0 ? value : 0.0;
    for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_down_sync(0xffffffffu, v, offset);
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
    if (lane == 0) partial[warp] = v;
    __syncthreads();
    if (warp == 0) {
        int n_warps = (blockDim.x + 31) >> 5;
        v = lane < n_warps ? partial[lane] : 0.0;
        for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_down_sync(0xffffffffu, v, offset);
        if (lane == 0 && first_segment >= 0) atomicAdd(out + first_segment, v);
    }
}

// atomic maximum for non-negative doubles: their bit patterns order like unsigned integers
__device__ __forceinline__ void atomic_max_nonneg(double* address, double value) {
    atomicMax(reinterpret_cast<unsigned long long*>(address), (unsigned long long)__double_as_longlong(value));
}
