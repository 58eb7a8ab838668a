/* tests/cuda_host/kernels/device_common.cuh -- host stand-in for spherevm/device_common.cuh, found
 * first on the include path when tests/cuda_host/kernels.cpp compiles the force kernels (.cu) for
 * the host. A kernel runs there one thread per call (h_set_thread picks the thread), so the thread
 * index is one block of one thread and the per-replica reduction is a plain running sum.
 */
#pragma once

struct host_index { unsigned int x; };
inline host_index blockIdx = {0}, blockDim = {1}, threadIdx = {0};

struct SegmentSum {
    const int* start;
    int n_segments;
    double* scratch;
    unsigned int* count;
};

// Threads run in item order, one per call: the sum is a plain running sum, started by the segment's
// first item (unless add).
inline void segment_sum(double value, int segment, const SegmentSum& sums, double* out, bool add = false)
{
    if (segment < 0) return;
    bool first = (long)blockIdx.x == sums.start[segment];
    out[segment] = first && !add ? value : out[segment] + value;
}
