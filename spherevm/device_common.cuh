// Reductions shared by spherevm's kernels: per-replica (segmented) sums that give bitwise the same
// result on every run, in any order of blocks (no floating-point atomics), so that a GPU run repeats
// exactly: restarts, sweeps on several GPUs, narrowed minimisations (docs/random.md, "Repeatability").
//
// Items (cells or vertices) are one per thread, i = blockIdx.x * blockDim.x + threadIdx.x, and the
// segments (replicas) are contiguous ranges start[s]..start[s+1] of items. Each block sums the run of
// every segment inside its tile of items in a fixed order (segment_sums). A segment inside one tile
// is then complete and written at once. A segment over several tiles leaves its part in its first
// tile in first[s] and its part in each later tile t in head[t] (slots that one block alone
// writes); each of its blocks then takes a ticket (count[s]), and the block with the last ticket
// adds the parts in tile order (segment_finish_warp or segment_finish_block, the same order) and
// sets the ticket back to zero.
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
// that finished them, which may read the sums it wrote): nothing, by default.
struct SegmentDone {
    __device__ void operator()(int) const {}
};

// Sum j's scratch: head[t] holds a segment's part in tile t, head[gridDim.x + s] segment s's part in
// its first tile.
__device__ __forceinline__ double* segment_head(const SegmentSum& sums, int j)
{
    return sums.scratch + (long)j * (gridDim.x + sums.n_segments);
}

// A finished sum into out[s] (added to it if add).
__device__ __forceinline__ void segment_store(double* out, int s, double total, bool add)
{
    out[s] = add ? out[s] + total : total;
}

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

// The finishing block's total of values that lie in its first warp only (every lane calls it with
// thread lane's value; lane 0's result is the one used): butterflies in the warp, then over the
// block's warp totals, all of which but the first are zeros.
__device__ __forceinline__ double first_warp_total(double v)
{
    v = warp_butterfly_sum(v);
    return warp_butterfly_sum((threadIdx.x & 31) == 0 ? v : 0.0);
}

// Segments longer than this many tiles are finished by the whole block (segment_finish_block); the
// others by one warp (segment_finish_warp), with the same bits.
#define SEGMENT_WARP_TILES 33

// Segment s over tiles t0..t1 (at most SEGMENT_WARP_TILES), its N sums finished by the calling warp
// (all 32 lanes) in segment_finish_block's order: lane i holds what thread i holds there (the first
// part plus tile t0 + 1 in lane 0, tile t0 + 1 + i in lane i), added up as first_warp_total. Lane 0 writes
// out[j][s] (plus out[j][s] if add). The N sums' loads are in flight together.
template <int N>
__device__ __forceinline__ void segment_finish_warp(const SegmentSum& sums, int s, long t0, long t1,
                                                    double* const* out, bool add)
{
    int lane = threadIdx.x & 31;
    long t = t0 + 1 + lane;
    double v[N];
    for (int j = 0; j < N; ++j) {
        const double* head = segment_head(sums, j);
        v[j] = lane == 0 ? __ldcg(head + gridDim.x + s) : 0.0;
        if (t <= t1) v[j] += __ldcg(head + t);
    }
    for (int j = 0; j < N; ++j) {
        double total = first_warp_total(v[j]);
        if (lane == 0) segment_store(out[j], s, total, add);
    }
}

// Segments s0, s1 (-1: none) crossing this block's tile edges, finished by the whole block (every
// thread calls it) where this block's ticket is the segment's last: for each of the N sums, thread
// i adds the segment's tiles i, i + blockDim.x, ... after its first, in tile order (the N sums'
// loads in flight together, four tiles of each), then fixed butterflies in each warp and over the
// warps; then done(s).
template <int N, class Done>
__device__ void segment_finish_block(const SegmentSum& sums, int s0, int s1, double* const* outs, bool add,
                                     Done done)
{
    __shared__ int finishing[2];
    __shared__ double warp_total[N][32];
    long tile = blockDim.x, stride = blockDim.x;
    if (threadIdx.x < 2) {
        int k = threadIdx.x == 0 ? s0 : s1;
        finishing[threadIdx.x] = -1;
        if (k >= 0) {
            long t0 = sums.start[k] / tile, t1 = (sums.start[k + 1] - 1) / tile;
            if (atomicAdd(sums.count + k, 1u) == (unsigned int)(t1 - t0)) finishing[threadIdx.x] = k;
        }
    }
    __syncthreads();
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, n_warps = (blockDim.x + 31) >> 5;
    for (int f = 0; f < 2; ++f) {
        int k = finishing[f];
        if (k < 0) continue;                      // the same k in every thread
        long t0 = sums.start[k] / tile, t1 = (sums.start[k + 1] - 1) / tile;
        double v[N];
        for (int j = 0; j < N; ++j) v[j] = threadIdx.x == 0 ? __ldcg(segment_head(sums, j) + gridDim.x + k) : 0.0;
        long t = t0 + 1 + threadIdx.x;
        for (; t + 3 * stride <= t1; t += 4 * stride) {
            double part[N][4];
            for (int j = 0; j < N; ++j)
                for (int q = 0; q < 4; ++q) part[j][q] = __ldcg(segment_head(sums, j) + t + q * stride);
            for (int j = 0; j < N; ++j)
                for (int q = 0; q < 4; ++q) v[j] += part[j][q];
        }
        for (; t <= t1; t += stride)
            for (int j = 0; j < N; ++j) v[j] += __ldcg(segment_head(sums, j) + t);
        for (int j = 0; j < N; ++j) {
            double w = warp_butterfly_sum(v[j]);
            if (lane == 0) warp_total[j][warp] = w;
        }
        __syncthreads();
        if (warp == 0) {
            for (int j = 0; j < N; ++j) {
                double w = warp_butterfly_sum(lane < n_warps ? warp_total[j][lane] : 0.0);
                if (lane == 0) segment_store(outs[j], k, w, add);
            }
        }
        __syncthreads();
    }
    if (threadIdx.x < 2 && finishing[threadIdx.x] >= 0) {
        sums.count[finishing[threadIdx.x]] = 0u;
        done(finishing[threadIdx.x]);
    }
}

// N sums over the segments at once (value[j] is the item's term of sum j): out[j][s] (plus out[j][s]
// if add), each sum added in the same order as if it were summed alone, then done(s) in one thread.
// Every thread of the block calls it (it synchronises), at most once per kernel; a thread without
// an item passes segment -1 (only after the last item).
//
// The block's warps add their runs (segmented suffix sums), and the first thread of each run in
// the tile adds the warps it continues into. A segment inside the tile is then complete; the part
// of a segment that crosses a tile edge goes to the scratch, and the block takes a ticket for it.
// The block with a segment's last ticket adds its parts in tile order: one warp per segment over
// at most SEGMENT_WARP_TILES tiles (no block barrier after the ticket), the whole block for longer
// ones. The control flow is short on purpose: a block's time is its longest chain of dependent
// latencies (loads, barriers, the ticket), so the segment bounds are fetched while the sums are
// shuffled, and the segments inside the tile get their done(s) while the finishing warps wait on
// the scratch.
template <int N, class Done = SegmentDone>
__device__ void segment_sums(const double (&value)[N], int segment, const SegmentSum& sums, double* const* out,
                             bool add, Done done = Done())
{
    __shared__ double warp_first_part[N][32];
    __shared__ int warp_first_segment[32];
    __shared__ int warp_last_segment[32];
    __shared__ int crossing[2];                   // segments crossing the tile's edges (-1: none)
    __shared__ int crossing_tiles[2];             // and their tile counts
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, n_warps = (blockDim.x + 31) >> 5;
    long tile = blockDim.x;
    if (threadIdx.x < 2) crossing[threadIdx.x] = -1;
    int previous = __shfl_up_sync(0xffffffffu, segment, 1);
    int begin = 0, end = 0;                       // a run's first lane in the warp: its segment's items
    if (segment >= 0 && (lane == 0 || previous != segment)) {
        begin = sums.start[segment];
        end = sums.start[segment + 1];
    }
    double v[N];
    for (int j = 0; j < N; ++j) v[j] = segment >= 0 ? value[j] : 0.0;
    warp_segment_suffix<N>(v, segment);
    if (lane == 0) {
        for (int j = 0; j < N; ++j) warp_first_part[j][warp] = v[j];
        warp_first_segment[warp] = segment;
    }
    if (lane == 31) warp_last_segment[warp] = segment;
    __syncthreads();
    if (lane == 0) previous = warp > 0 ? warp_last_segment[warp - 1] : -2;
    bool inside = false;                          // this thread's run is a whole segment, complete
    if (segment >= 0 && previous != segment) {
        // the first thread of a run in the tile: the run's totals, over the warps it continues into
        long t0 = begin / tile, t1 = (end - 1) / tile;
        inside = t0 == t1;
        for (int j = 0; j < N; ++j) {
            double total = v[j];
            for (int w = warp + 1; w < n_warps && warp_first_segment[w] == segment; ++w) total += warp_first_part[j][w];
            if (inside) {
                segment_store(out[j], segment, total, add);
            } else {
                double* head = segment_head(sums, j);
                if (blockIdx.x == t0) head[gridDim.x + segment] = total;
                else head[blockIdx.x] = total;
            }
        }
        if (!inside) {
            int k = threadIdx.x == 0 ? 0 : 1;
            crossing[k] = segment;
            crossing_tiles[k] = (int)(t1 - t0 + 1);
        }
    }
    __threadfence();   // this block's parts are visible before its tickets are taken
    __syncthreads();
    int s0 = crossing[0], s1 = crossing[1];
    int longest = max(s0 >= 0 ? crossing_tiles[0] : 0, s1 >= 0 ? crossing_tiles[1] : 0);
    if (longest > SEGMENT_WARP_TILES) {
        if (inside) done(segment);
        segment_finish_block<N>(sums, s0, s1, out, add, done);
        return;
    }
    for (int k = warp; k < 2; k += n_warps) {     // warp k finishes s_k if its ticket is the last
        int s = k == 0 ? s0 : s1;
        if (s < 0) continue;
        long t0 = sums.start[s] / tile, t1 = (sums.start[s + 1] - 1) / tile;
        unsigned int ticket = lane == 0 ? atomicAdd(sums.count + s, 1u) : 0u;
        if (__shfl_sync(0xffffffffu, ticket, 0) != (unsigned int)(t1 - t0)) continue;
        segment_finish_warp<N>(sums, s, t0, t1, out, add);
        if (lane == 0) {
            sums.count[s] = 0u;
            done(s);
        }
    }
    if (inside) done(segment);
}

// One sum in a kernel: out[s] = the sum of value over segment s (out[s] += it if add).
__device__ void segment_sum(double value, int segment, const SegmentSum& sums, double* out, bool add = false)
{
    const double values[1] = {value};
    segment_sums<1>(values, segment, sums, &out, add);
}

// One block holding one whole segment [s0, s1) gives its sums the bits segment_sums gives them in a
// launch of `tile` threads a block over all the items (the fused small-tissue steps,
// spherevm/tissue_steps.cu). Thread t's k-th item is item g = (s0 & ~31) + t +
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
// (segment_sums); over several tiles (at most 32), the finish's order: the first part plus
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
        out[j] = first_warp_total(v);
    }
}
