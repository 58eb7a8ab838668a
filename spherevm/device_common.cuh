// Reductions shared by spherevm's kernels: per-replica (segmented) sums that give bitwise the same
// result on every run, in any order of blocks (no floating-point atomics), so that a GPU run repeats
// exactly: restarts, sweeps on several GPUs, narrowed minimisations (docs/random.md, "Repeatability").
//
// Items (cells or vertices) are one per thread, i = blockIdx.x * blockDim.x + threadIdx.x, and the
// segments (replicas) are contiguous ranges start[s]..start[s+1] of items. Each block sums the run of
// every segment inside its tile of items in a fixed order (segment_sum_partial). A segment inside
// one tile is then complete and written at once. A segment over several tiles leaves its part in
// its first tile in first[s] and its part in each later tile t in head[t] (slots that one block
// alone writes); each of its blocks then takes a ticket (count[s]), and the block with the last
// ticket adds the parts in tile order (segment_sum_finish) and sets the ticket back to zero.
#pragma once

// The kernel arguments of a kernel's sums (spherevm.device.segment_sums builds them): start
// (n_segments + 1 item offsets), scratch (n_sums * (gridDim.x + n_segments) doubles: head, then
// first, per sum) and count (n_segments zeros, left at zero by every launch).
struct SegmentSum {
    const int* start;
    int n_segments;
    double* scratch;
    unsigned int* count;
};

// What a kernel does with a segment once its sums are final (done(s), in one thread of the block
// that finished them: segment_sum_partial's or segment_sum_finish's): nothing, by default.
struct SegmentDone {
    __device__ void operator()(int) const {}
};

// The (at most two) segments that cross this block's tile edges, found by segment_sum_partial.
__shared__ int segment_sum_crossing[2];

// Segmented suffix sums inside a warp (every lane calls it): each lane's v[j] ends as the sum from
// itself to the end of its segment's run in the warp, always in the same order.
template <int N>
__device__ __forceinline__ void warp_segment_suffix(double (&v)[N], int segment)
{
    int lane = threadIdx.x & 31;
    for (int offset = 1; offset < 32; offset <<= 1) {
        int other_segment = __shfl_down_sync(0xffffffffu, segment, offset);
        bool same = lane + offset < 32 && other_segment == segment;
        for (int j = 0; j < N; ++j) {
            double other = __shfl_down_sync(0xffffffffu, v[j], offset);
            if (same) v[j] += other;
        }
    }
}

// The sum of a warp's values in fixed butterflies (every lane calls it; lane 0's is the one used).
__device__ __forceinline__ double warp_butterfly_sum(double v)
{
    for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_xor_sync(0xffffffffu, v, offset);
    return v;
}

// N sums of this block's items at once (value[j] is the item's term of sum j): out[j][s] (plus
// out[j][s] if add) for a segment inside the tile, the parts of the others to the scratch. Each sum
// is added in the same order as if it were summed alone; together they share the segment shuffles
// and the block's two barriers. Every thread of the block calls it (it synchronises); a thread
// without an item passes segment -1 (only after the last item). done(s) after a segment inside the
// tile is written (the call's N sums of it final).
template <int N, class Done = SegmentDone>
__device__ void segment_sum_partial(const double (&value)[N], int segment, const SegmentSum& sums,
                                    double* const* out, bool add, Done done = Done())
{
    __shared__ double warp_first_part[N][32];
    __shared__ int warp_first_segment[32];
    __shared__ int warp_last_segment[32];
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, n_warps = (blockDim.x + 31) >> 5;
    if (threadIdx.x < 2) segment_sum_crossing[threadIdx.x] = -1;
    // segmented suffix sums inside the warp: each lane ends with the sum from itself to the end of
    // its segment's run in the warp, always in the same order
    double v[N];
    for (int j = 0; j < N; ++j) v[j] = segment >= 0 ? value[j] : 0.0;
    warp_segment_suffix<N>(v, segment);
    int previous = __shfl_up_sync(0xffffffffu, segment, 1);
    if (lane == 0) {
        for (int j = 0; j < N; ++j) warp_first_part[j][warp] = v[j];
        warp_first_segment[warp] = segment;
    }
    if (lane == 31) warp_last_segment[warp] = segment;
    __syncthreads();
    if (lane == 0) previous = warp > 0 ? warp_last_segment[warp - 1] : -2;
    if (segment >= 0 && previous != segment) {
        // the first thread of a run in the tile: the run's totals, over the warps it continues into
        long tile = blockDim.x, t0 = sums.start[segment] / tile, t1 = (sums.start[segment + 1] - 1) / tile;
        for (int j = 0; j < N; ++j) {
            double total = v[j];
            for (int w = warp + 1; w < n_warps && warp_first_segment[w] == segment; ++w) total += warp_first_part[j][w];
            if (t0 == t1) {
                out[j][segment] = add ? out[j][segment] + total : total;
            } else {
                double* head = sums.scratch + (long)j * (gridDim.x + sums.n_segments);
                if (blockIdx.x == t0) head[gridDim.x + segment] = total;
                else head[blockIdx.x] = total;
            }
        }
        if (t0 != t1) segment_sum_crossing[threadIdx.x == 0 ? 0 : 1] = segment;
        else done(segment);
    }
    __syncthreads();   // the shared scratch may be reused by the next call
}

// After the block's segment_sum_partial calls (all threads): the segments whose last part this
// block wrote are added up, outs[j][s] (plus outs[j][s] if add) for the n_sums sums; then done(s).
template <class Done = SegmentDone>
__device__ void segment_sum_finish(const SegmentSum& sums, double* const* outs, int n_sums, bool add,
                                   Done done = Done())
{
    __shared__ int finishing[2];
    __threadfence();   // this block's parts are visible before its tickets are taken
    __syncthreads();
    long tile = blockDim.x;
    if (threadIdx.x < 2) {
        int s = segment_sum_crossing[threadIdx.x];
        finishing[threadIdx.x] = -1;
        if (s >= 0) {
            long t0 = sums.start[s] / tile, t1 = (sums.start[s + 1] - 1) / tile;
            if (atomicAdd(sums.count + s, 1u) == (unsigned int)(t1 - t0)) finishing[threadIdx.x] = s;
        }
    }
    __syncthreads();
    // the whole block per (finishing segment, sum): thread i adds the segment's tiles i, i + blockDim.x,
    // ... after its first (four loads in flight, the additions in tile order), then fixed butterflies
    // in each warp and over the warps
    __shared__ double warp_total[32];
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, n_warps = (blockDim.x + 31) >> 5;
    for (int task = 0; task < 2 * n_sums; ++task) {
        int s = finishing[task / n_sums], j = task % n_sums;
        if (s < 0) continue;                      // the same s in every thread
        long t0 = sums.start[s] / tile, t1 = (sums.start[s + 1] - 1) / tile, stride = blockDim.x;
        const double* head = sums.scratch + (long)j * (gridDim.x + sums.n_segments);
        double v = threadIdx.x == 0 ? __ldcg(head + gridDim.x + s) : 0.0;
        long t = t0 + 1 + threadIdx.x;
        for (; t + 3 * stride <= t1; t += 4 * stride) {
            double a = __ldcg(head + t), b = __ldcg(head + t + stride), c = __ldcg(head + t + 2 * stride),
                   d = __ldcg(head + t + 3 * stride);
            v += a; v += b; v += c; v += d;
        }
        for (; t <= t1; t += stride) v += __ldcg(head + t);
        v = warp_butterfly_sum(v);
        if (lane == 0) warp_total[warp] = v;
        __syncthreads();
        if (warp == 0) {
            v = warp_butterfly_sum(lane < n_warps ? warp_total[lane] : 0.0);
            if (lane == 0) outs[j][s] = add ? outs[j][s] + v : v;
        }
        __syncthreads();
    }
    __syncthreads();
    if (threadIdx.x < 2 && finishing[threadIdx.x] >= 0) {
        sums.count[finishing[threadIdx.x]] = 0u;
        done(finishing[threadIdx.x]);
    }
}

// One sum in a kernel: out[s] = the sum of value over segment s (out[s] += it if add).
__device__ void segment_sum(double value, int segment, const SegmentSum& sums, double* out, bool add = false)
{
    const double values[1] = {value};
    segment_sum_partial<1>(values, segment, sums, &out, add);
    segment_sum_finish(sums, &out, 1, add);
}

// One block holding one whole segment [s0, s1) gives its sums the bits segment_sum_partial and
// segment_sum_finish give them in a launch of `tile` threads a block over all the items (the fused
// small-tissue steps, spherevm/tissue_steps.cu). Thread t's k-th item is item g = (s0 & ~31) + t +
// k * blockDim.x (blockDim.x a multiple of 32), so the block's warps are that launch's warps. Every
// thread calls block_segment_warp once per k, with `mine` = s0 <= g < s1: it leaves each of the
// warp's suffix sums at lane 0 in part[j * (n_warps + 1) + w] (w: the warp's place from s0 & ~31),
// and at the segment's first item in part[j * (n_warps + 1) + n_warps].
template <int N>
__device__ __forceinline__ void block_segment_warp(const double (&value)[N], bool mine, long g, long s0, int n_warps,
                                                   double* part)
{
    double v[N];
    for (int j = 0; j < N; ++j) v[j] = mine ? value[j] : 0.0;
    warp_segment_suffix<N>(v, mine ? 0 : -1);
    int w = (int)((g - (s0 & ~31L)) >> 5);
    if ((threadIdx.x & 31) == 0 && w < n_warps)
        for (int j = 0; j < N; ++j) part[j * (n_warps + 1) + w] = v[j];
    if (g == s0)
        for (int j = 0; j < N; ++j) part[j * (n_warps + 1) + n_warps] = v[j];
}

// After every block_segment_warp (and a barrier): the N sums, in lane 0 of the calling warp (its 32
// lanes call it). Per tile, its first item's suffix plus the next warps' in the tile, in order
// (segment_sum_partial); over several tiles (at most 32), the finish's order: the first part plus
// the second tile's in thread 0, the others' tiles in threads 1.., butterflies in the warp, then
// over the finishing block's warps (warp 0's total, zeros from the others).
template <int N>
__device__ __forceinline__ void block_segment_total(const double* part, long s0, long s1, int n_warps, long tile,
                                                    double (&out)[N])
{
    int lane = threadIdx.x & 31;
    long base = s0 & ~31L, t0 = s0 / tile, t1 = (s1 - 1) / tile;
    int n_tiles = (int)(t1 - t0 + 1);
    for (int j = 0; j < N; ++j) {
        const double* p = part + j * (n_warps + 1);
        double total = 0.0;
        if (lane < n_tiles) {
            long t = t0 + lane, first = t == t0 ? s0 : t * tile, end = min(s1, (t + 1) * tile);
            total = t == t0 ? p[n_warps] : p[(first - base) >> 5];
            for (long w = ((first >> 5) + 1) << 5; w < end; w += 32) total += p[(w - base) >> 5];
        }
        if (n_tiles == 1) {
            out[j] = total;
            continue;
        }
        double next = __shfl_down_sync(0xffffffffu, total, 1);
        double v = lane == 0 ? total : 0.0;
        if (lane + 1 < n_tiles) v += next;
        v = warp_butterfly_sum(v);
        out[j] = warp_butterfly_sum(lane == 0 ? v : 0.0);
    }
}
