// Reductions shared by spherevm's kernels: per-replica (segmented) sums.
#pragma once

struct AddOp { __device__ static double apply(double a, double b) { return a + b; }
               __device__ static void commit(double* p, double v) { atomicAdd(p, v); } };

// Combine `value` into out[segment] with Op (a sum). Threads of a block usually share one segment (replicas are
// contiguous ranges): then the block reduces in shared memory and issues one atomic; otherwise
// every thread adds its own value. Every thread of the block must call it (it synchronises);
// threads without work pass value 0 and any valid segment, or segment -1 to skip.
template <class Op>
__device__ void segmented_block_reduce(double value, int segment, double* out) {
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
        // segments are contiguous runs of threads: a segmented suffix scan inside each warp leaves
        // every run's total in its first lane, which commits it (one atomic per run and warp)
        double v = value;
        int lane = threadIdx.x & 31;
        for (int offset = 1; offset < 32; offset <<= 1) {
            double other = __shfl_down_sync(0xffffffffu, v, offset);
            int other_segment = __shfl_down_sync(0xffffffffu, segment, offset);
            if (lane + offset < 32 && other_segment == segment) v = Op::apply(v, other);
        }
        int previous = __shfl_up_sync(0xffffffffu, segment, 1);
        if (segment >= 0 && (lane == 0 || previous != segment)) Op::commit(out + segment, v);
        __syncthreads();
        return;
    }
    double v = segment >= 0 ? value : 0.0;
    for (int offset = 16; offset > 0; offset >>= 1) v = Op::apply(v, __shfl_down_sync(0xffffffffu, v, offset));
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
    if (lane == 0) partial[warp] = v;
    __syncthreads();
    if (warp == 0) {
        int n_warps = (blockDim.x + 31) >> 5;
        v = lane < n_warps ? partial[lane] : 0.0;
        for (int offset = 16; offset > 0; offset >>= 1) v = Op::apply(v, __shfl_down_sync(0xffffffffu, v, offset));
        if (lane == 0 && first_segment >= 0) Op::commit(out + first_segment, v);
    }
    __syncthreads();   // the shared scratch may be reused by the next call
}

__device__ __forceinline__ void segmented_block_add(double value, int segment, double* out) {
    segmented_block_reduce<AddOp>(value, segment, out);
}

