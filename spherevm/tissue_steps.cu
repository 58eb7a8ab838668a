// Many Brownian steps of small tissues in one launch (spherevm/tissue_steps.py): a cluster of
// TISSUE_CLUSTER thread blocks per tissue (replica) runs `steps` whole steps, each T1's pass, the
// vertex model's forces and the Brownian move, with barriers between the phases and no launch,
// memset or host between the steps. The phases are limited by one SM's double-precision throughput
// (a 1,024-cell tissue's forces take about 20 us on one H200 SM), so a larger tissue spreads its
// cells and vertices over the cluster's blocks (Hopper thread block clusters): each block keeps a
// copy of the tissue's positions and cell coefficients in its shared memory and sends what it
// computes to the others' copies (distributed shared memory). T1's pass is cheap and runs in the
// cluster's first block; the tissue's topology stays in global memory. On the sphere each block also
// keeps every vertex's 1 / |x| (KeptNorm, geometry/surface.cuh), computed once after each move or
// flip: the cells and vertex forces would otherwise each take an rsqrt of every vertex they read.
// Every phase runs the same device function as the general kernels (vertex_model.cuh, t1_pass.cuh,
// brownian.cuh) on the same indices, so the trajectory is the general path's bit for bit: the same
// Philox draws (counted by global vertex index and timestep), the same flips (lowest edge index
// wins), the same arithmetic. Compiled once per surface and cluster size.
#include "plugins/forces/vertex_model.cuh"
#include "plugins/updaters/t1_pass.cuh"
#include "plugins/integrators/brownian.cuh"
#include "plugins/integrators/fire.cuh"
#include "device_common.cuh"

#ifndef TISSUE_CLUSTER
#define TISSUE_CLUSTER 1
#endif
#ifndef TISSUE_THREADS
#define TISSUE_THREADS 1024
#endif

#if TISSUE_CLUSTER > 1
#define TISSUE_CLUSTER_DIMS __cluster_dims__(TISSUE_CLUSTER, 1, 1)
// Every thread of the cluster: what each wrote before (shared memory of any block, global memory)
// is seen by all after.
__device__ __forceinline__ void cluster_sync()
{
    asm volatile("barrier.cluster.arrive.release.aligned;\n\tbarrier.cluster.wait.acquire.aligned;" ::: "memory");
}
// The address of p (this block's shared memory) in the shared memory of the cluster's block `rank`.
template <class T>
__device__ __forceinline__ T* cluster_map(T* p, unsigned int rank)
{
    unsigned long long out;
    asm volatile("mapa.u64 %0, %1, %2;" : "=l"(out) : "l"(p), "r"(rank));
    return (T*)out;
}
#else
#define TISSUE_CLUSTER_DIMS
__device__ __forceinline__ void cluster_sync() { __syncthreads(); }
template <class T>
__device__ __forceinline__ T* cluster_map(T* p, unsigned int) { return p; }
#endif

// x into item i of the array at `offset` (doubles, indexed as the tissue's copy is) in every other
// block's shared memory.
__device__ __forceinline__ void to_others(double* const* bases, int rank, long offset, long i, vec3 x)
{
    for (int q = 0; q < TISSUE_CLUSTER; ++q)
        if (q != rank) store3(bases[q] + offset, i, x);
}

// The vertex model's terms (vm_cell_terms into coef) of `count` cells, cell(0) .. cell(count - 1),
// by the calling block, the vertices' directions from norm (Surface::directions); sent(c) after
// each. On a surface that splits a cell's corners (the sphere: Surface::split_corners), a cell takes
// `lanes` neighbouring threads (a power of two, at most 8): each lane computes every lanes-th
// corner's arc and fan factor (Surface::cell_corner), and every lane adds them in the cell's order
// (Surface::add_corner), so the chain of a cell's atan2s is shortened and the bits are
// cell_measures' whatever the lanes. Every thread of the block calls it, with S = Surface.
template <class S, class Cell, class Sent>
__device__ __forceinline__ void tissue_cells(const double* P, KeptNorm norm, const int* cell_vertices,
                                             const int* sides, int max_sides, typename S::Size s, int count,
                                             Cell cell, int lanes, const double* kA, const double* kP,
                                             const double* A0, const double* P0, double* coef, Sent sent)
{
    const int tid = threadIdx.x, stride = blockDim.x;
    if constexpr (S::split_corners) {
        if (lanes > 1) {
            const unsigned all = 0xffffffffu;
            const int lane = tid & (lanes - 1), groups = stride / lanes;
            for (int first = 0; first < count; first += groups) {   // the same number of rounds in every thread
                const int i = first + tid / lanes;
                const bool mine = i < count;
                const int c = cell(mine ? i : 0);
                const int n = mine ? sides[c] : 0;
                const int* row = cell_vertices + (long)c * max_sides;
                const vec3 a = S::direction(P, row[0], norm);
                typename S::CellSum sum = {0.0, 1.0, 0.0};
                const int rounds = __reduce_max_sync(all, (n + lanes - 1) / lanes);
                for (int q = 0; q < rounds; ++q) {
                    typename S::Corner k = {0.0, 0.0, 0.0};
                    if (q * lanes + lane < n) k = S::cell_corner(P, row, n, q * lanes + lane, a, norm);
                    for (int l = 0; l < lanes; ++l) {
                        typename S::Corner kl = {__shfl_sync(all, k.half, l, lanes), __shfl_sync(all, k.num, l, lanes),
                                                 __shfl_sync(all, k.den, l, lanes)};
                        if (q * lanes + l < n) S::add_corner(&sum, kl);
                    }
                }
                if (mine && lane == 0) {
                    double A, Pc;
                    S::finish_measures(sum, s, &A, &Pc);
                    vm_cell_terms(A, Pc, c, s, kA, kP, A0, P0, coef);
                    sent(c);
                }
            }
            return;
        }
    }
    for (int i = tid; i < count; i += stride) {   // one thread a cell
        const int c = cell(i);
        double A, Pc;
        S::cell_measures(P, cell_vertices + (long)c * max_sides, sides[c], s, &A, &Pc, norm);
        vm_cell_terms(A, Pc, c, s, kA, kP, A0, P0, coef);
        sent(c);
    }
}

// Threads a cell in tissue_cells (cb cells): as many as a block of at most 512 threads has for its
// cells, a power of two up to 8. A block of more threads keeps one a cell: its SM is busy with its
// many warps, and the lanes' shuffles and repeated sums only add work (one H200: 8 x 1,024 cells on
// 2 blocks of 1,024 threads, 18 % longer on two lanes a cell without kept norms; on 4 blocks of 512
// threads, 6 % shorter with the kept norms; 1,024 x 32 and 64 x 64 cells, 2-5 warps a block, 4-14 %
// shorter).
__device__ __forceinline__ int tissue_cell_lanes(int cb)
{
    int lanes = 1;
    while (blockDim.x <= 512 && lanes < 8 && blockDim.x / (2 * lanes) >= cb) lanes *= 2;
    return lanes;
}

// Vertex v's 1 / |x| into inv (KeptNorm's array; nothing where the surface's functions use no
// directions), in every block of the cluster (bases: their shared memory; at: the array's offset).
__device__ __forceinline__ void keep_norm(double* const* bases, long at, const double* P, long v)
{
    if constexpr (Surface::directions) {
        const double inv = RsqrtNorm()(P, v);
        for (int q = 0; q < TISSUE_CLUSTER; ++q) bases[q][at + v] = inv;
    }
}

// T1's arguments of the fused steps: its parameters (chord2, new_length, length_factor), its
// candidate room (a slot per edge, the tissue's from 3 vertex_start[r] / 2 on), its per-pass
// counters (flips, refused: the last pass's are left, as t1_apply leaves them) and running totals,
// step_need[j] (the widest C3/C4 row of a claimant in step j: tissue_steps_finish turns it into the
// width t1_apply grows), and with `logging` the flip log (pass0: the number of the launch's first
// pass less one, as t1_detect counts).
struct TissueT1 {
    const double* chord2;
    const double* new_length;
    double length_factor;
    int* cand;
    double* cand_len;
    int* flips;
    int* refused;
    unsigned long long* total_flips;
    unsigned long long* total_refused;
    int* step_need;
    int* log_count;
    int* log;
    int logging;
    int pass0;
};

// T1's pass of tissue r (vertices v0..v1), the `step`-th of the launch, in two parts with a barrier
// between: tissue_t1_detect lists the short edges of vertices vb0..vb1 (every block of the tissue
// its own), tissue_t1_settle checks and claims (a warp a candidate: t1_check_candidate_warp) and
// applies them (t1_pass.cuh), in one block. n_cand: the tissue's candidate count (in the settling
// block's shared memory; zero when a pass begins: the caller sets it back to zero once every block
// has read it); claim: the tissue's claims (all free between passes).
__device__ __forceinline__ void tissue_t1_detect(const double* P, const int* vn, const int* vc, Surface::Size s,
                                                 int r, int vb0, int vb1, int v0, int v1, bool flipping,
                                                 const TissueT1& t1, int* n_cand, bool settling)
{
    const int room0 = (3 * v0) / 2, room = (3 * v1) / 2 - room0;
    if (settling && threadIdx.x == 0) { t1.flips[r] = 0; t1.refused[r] = 0; }
    if (flipping)
        for (int u = vb0 + threadIdx.x; u < vb1; u += blockDim.x)
            t1_detect_vertex(P, vn, vc, s, t1.chord2[r], r, u, n_cand, t1.cand + (long)room0 * CAND_INTS,
                             t1.cand_len + room0, room);
}

// flipped(e) after each flip.
template <class Flipped>
__device__ __forceinline__ void tissue_t1_settle(double* P, int* vn, int* vc, int* cell_vertices, int* sides,
                                                 int max_sides, Surface::Size s, int r, int v0, int v1,
                                                 const TissueT1& t1, int* claim, int* n_cand, int step,
                                                 Flipped flipped)
{
    const int tid = threadIdx.x, stride = blockDim.x;
    const int room0 = (3 * v0) / 2, room = (3 * v1) / 2 - room0;
    int* cand = t1.cand + (long)room0 * CAND_INTS;
    double* len = t1.cand_len + room0;
    const int n = min(*n_cand, room);
    for (int i = tid >> 5; i < n; i += stride >> 5) {   // a warp a candidate (blockDim.x: a multiple of 32)
        int* e = cand + (long)i * CAND_INTS;
        bool kept = t1_check_candidate_warp(P, vn, sides, cell_vertices, max_sides, s,
                                            t1_full_length(t1.new_length[r], t1.length_factor, len[i]), claim, e);
        if ((tid & 31) != 0) continue;
        if (kept) {
            atomicMax(t1.step_need + step, max(sides[e[9]], sides[e[10]]));
        } else {
            atomicAdd(t1.refused + r, 1);
            atomicAdd(t1.total_refused + r, 1ull);
        }
    }
    __syncthreads();
    for (int i = tid; i < n; i += stride) {
        const int* e = cand + (long)i * CAND_INTS;
        if (t1_apply_candidate(P, vn, vc, cell_vertices, sides, max_sides, s,
                               t1_full_length(t1.new_length[r], t1.length_factor, len[i]), claim, e)) {
            atomicAdd(t1.flips + r, 1);
            atomicAdd(t1.total_flips + r, 1ull);
            if (t1.logging) t1_log_flip(t1.log_count, t1.log, t1.pass0 + step + 1, e);
            flipped(e);
        }
    }
}

// The arguments both fused kernels take first (tissue_steps.TissueSteps.run passes them): the
// State's positions and topology, the per-replica vertex and cell offsets and sizes, the vertex
// model's parameters, then T1's (t1: 0 no T1 pass; TissueT1; log_pass: the flip log's pass count
// before the launch).
#define TISSUE_COMMON_PARAMS \
    double* __restrict__ pos, int* vn, int* vc, int* cell_vertices, int* sides, \
    const int* __restrict__ vertex_start, const int* __restrict__ cell_start, const double* __restrict__ size, \
    int max_sides, const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0, \
    const double* __restrict__ P0, int t1, const bool* __restrict__ active, const double* __restrict__ chord2, \
    const double* __restrict__ new_length, double length_factor, int* cand, double* cand_len, \
    int* __restrict__ flips, int* __restrict__ refused, unsigned long long* __restrict__ total_flips, \
    unsigned long long* __restrict__ total_refused, int* __restrict__ log_count, int* __restrict__ log, int logging, \
    const int* __restrict__ log_pass, int* __restrict__ step_need

// At most TISSUE_THREADS threads a block (tissue_steps.layout's bound). Shared memory of each block, in
// doubles (tissue_steps.py computes the same, in bytes): two copies of the positions (3 nv each: the
// step's, and the next, which the move writes while other blocks still read the step's), the cell
// coefficients (2 nc), on the sphere two copies of the kept 1 / |x| (nv each, as the positions), the
// forces of the block's vertices (3 ceil(nv / TISSUE_CLUSTER)), then the T1 claims (nc ints) and the
// pass's flips (ceil(nc / 4) ints).
//
// A step: every block lists the short edges of its vertices and computes its cells' coefficients on
// the step's positions (a barrier); if any edge is short, the first block checks and flips them and
// computes again the four cells of each flip (a flip moves and re-links only its four cells, and the
// flips of a pass share no cell: T1's claims), then a barrier; then the forces and the move of every
// block's vertices (a barrier). The cells are those the general path computes after T1's pass, with
// two or three barriers a step instead of four.
extern "C" __global__ void __launch_bounds__(TISSUE_THREADS) TISSUE_CLUSTER_DIMS tissue_steps(
    TISSUE_COMMON_PARAMS, const double* __restrict__ amp,
    const double* __restrict__ length_unit, double mu, double dt, double max_step, unsigned int seed,
    unsigned long long* __restrict__ error, unsigned long long step0, int steps)
{
    extern __shared__ double shared[];
    __shared__ int n_cand, n_flipped;
    __shared__ double* bases[TISSUE_CLUSTER];
    const int r = blockIdx.x / TISSUE_CLUSTER, rank = blockIdx.x % TISSUE_CLUSTER;   // a 1-D cluster's rank
    const int tid = threadIdx.x, stride = blockDim.x;
    const int v0 = vertex_start[r], v1 = vertex_start[r + 1], c0 = cell_start[r], c1 = cell_start[r + 1];
    const int nv = v1 - v0, nc = c1 - c0;
    const int vchunk = (nv + TISSUE_CLUSTER - 1) / TISSUE_CLUSTER, cchunk = (nc + TISSUE_CLUSTER - 1) / TISSUE_CLUSTER;
    const int vb0 = min(v1, v0 + rank * vchunk), vb1 = min(v1, vb0 + vchunk);   // this block's vertices
    const int cb0 = min(c1, c0 + rank * cchunk), cb1 = min(c1, cb0 + cchunk);   // and cells
    // the arrays, as offsets from a block's shared memory that global indices address (copy k of the
    // positions at at_pos + 3 nv k, of the kept norms at at_inv + kept k: scalars, not arrays that a
    // step's index would leave in local memory)
    const long at_pos = -3L * v0;
    const long at_coef = 6L * nv - 2L * c0;
    const int kept = Surface::directions ? nv : 0;
    const long at_inv = 6L * nv + 2L * nc - v0;
    double* coef = shared + at_coef;
    double* F = shared + 6L * nv + 2L * nc + 2L * kept - 3L * vb0;
    int* claim = (int*)(shared + 6L * nv + 2L * nc + 2L * kept + 3L * vchunk) - c0;
    int* flipped = claim + c1;   // the first block's: the candidates (indices into t1.cand) its pass flipped
    if (tid < TISSUE_CLUSTER) bases[tid] = cluster_map(shared, tid);
    if (tid == 0) { n_cand = 0; n_flipped = 0; }
    int* const count = cluster_map(&n_cand, 0);   // the first block's
    for (int j = tid; j < 3 * nv; j += stride) shared[j] = pos[3L * v0 + j];
    __syncthreads();
    if (Surface::directions)
        for (int v = v0 + tid; v < v1; v += stride) shared[at_inv + v] = RsqrtNorm()(shared + at_pos, v);
    for (int c = c0 + tid; c < c1; c += stride) claim[c] = 0x7fffffff;
    const Surface::Size s = Surface::size(size, r);
    const bool flipping = t1 && active[r];
    const TissueT1 t1_args = {chord2, new_length, length_factor, cand, cand_len, flips, refused, total_flips,
                              total_refused, step_need, log_count, log, logging, t1 ? *log_pass : 0};
    const int lanes = tissue_cell_lanes(cb1 - cb0);
    auto send = [&](int c) {   // a cell's coefficients to the other blocks
        for (int q = 0; q < TISSUE_CLUSTER; ++q)
            if (q != rank) {
                bases[q][at_coef + 2L * c] = coef[2L * c];
                bases[q][at_coef + 2L * c + 1] = coef[2L * c + 1];
            }
    };
    cluster_sync();   // every block of the cluster has started (its shared memory may be written)
    int now = 0;
    for (int step = 0; step < steps; ++step) {
        unsigned long long timestep = step0 + step;
        const long pos_now = at_pos + 3L * nv * now, pos_next = at_pos + 3L * nv * (1 - now);
        const long inv_now = at_inv + (long)kept * now, inv_next = at_inv + (long)kept * (1 - now);
        double* P = shared + pos_now;
        double* next = shared + pos_next;
        const KeptNorm norm = {shared + inv_now};
        if (t1)   // T1's pass begins: every block lists the short edges of its vertices
            tissue_t1_detect(P, vn, vc, s, r, vb0, vb1, v0, v1, flipping, t1_args, count, rank == 0);
        // the vertex model (vertex_model.cuh): this block's cells, their coefficients to the other blocks
        tissue_cells<Surface>(P, norm, cell_vertices, sides, max_sides, s, cb1 - cb0, [=](int i) { return cb0 + i; },
                              lanes, kA, kP, A0, P0, coef, send);
        cluster_sync();   // the candidates listed, the coefficients everywhere
        if (t1 && *count > 0) {   // (the same in every block) T1's check and flips, in the first block
            if (rank == 0) {
                tissue_t1_settle(P, vn, vc, cell_vertices, sides, max_sides, s, r, v0, v1, t1_args, claim, &n_cand,
                                 step, [&](const int* e) {   // the flipped edge, everywhere
                                     for (int k = 0; k < 3; k += 2) {
                                         to_others(bases, rank, pos_now, e[k], load3(P, e[k]));
                                         keep_norm(bases, inv_now, P, e[k]);
                                     }
                                     flipped[atomicAdd(&n_flipped, 1)] = (int)((e - t1_args.cand) / CAND_INTS);
                                 });
                __syncthreads();   // every flip applied and listed: its four cells (C1..C4) again
                const int fixes = 4 * n_flipped;
                auto fixed = [&](int i) {   // cell (i & 3) of flip i >> 2: C1..C4 of its candidate
                    return t1_args.cand[(long)flipped[i >> 2] * CAND_INTS + 7 + (i & 3)];
                };
                tissue_cells<Surface>(P, norm, cell_vertices, sides, max_sides, s, fixes, fixed,
                                      tissue_cell_lanes(fixes), kA, kP, A0, P0, coef, send);
            }
            cluster_sync();   // the flips and their cells everywhere; every block has read the count
            if (rank == 0 && tid == 0) { n_cand = 0; n_flipped = 0; }
        }
        for (int v = vb0 + tid; v < vb1; v += stride) {   // this block's vertices: force, then the move (brownian.cuh)
            store3(F, v, Surface::vertex_force(P, vn, vc, v, s, coef, NoExtra(), norm));
            store3(next, v, load3(P, v));
            brownian_vertex(next, F, v, vc, s, amp[r], length_unit[r], nullptr, 0, mu, dt, 0.0, 0.0, max_step, seed,
                            timestep, error);
            to_others(bases, rank, pos_next, v, load3(next, v));
            keep_norm(bases, inv_next, next, v);
        }
        cluster_sync();
        now = 1 - now;
    }
    for (int j = 3 * (vb0 - v0) + tid; j < 3 * (vb1 - v0); j += stride)
        pos[3L * v0 + j] = shared[at_pos + 3L * nv * now + 3L * v0 + j];
}

// Many FIRE iterations of Simulation.minimize in one launch, a thread block per tissue: each
// iteration the vertex model's forces, FIRE's per-replica sums (in device_common.cuh's order for
// a launch of `tile` threads a block: block_segment_warp / block_segment_total), its control
// (thread 0) and move (fire.cuh), then T1's pass of the next timestep, as minimize orders them.
// A stopped replica (fire_active false) only has its velocities zeroed (and T1's counters, as each pass
// does). Shared memory, in doubles (tissue_steps.py computes the same, in bytes): the positions,
// forces and velocities (3 nv each), the cell coefficients (2 nc), on the sphere the kept 1 / |x|
// (nv, KeptNorm: after each move and flip), the sums' warp parts
// (3 (n_warps + 1), n_warps the warps from v0 & ~31 to v1), then the T1 claims (nc ints).
extern "C" __global__ void __launch_bounds__(TISSUE_THREADS) tissue_minimize(
    TISSUE_COMMON_PARAMS, int reset_velocities,
    const bool* __restrict__ fire_active, double* __restrict__ vel, double* __restrict__ dt,
    double* __restrict__ alpha, long long* __restrict__ n_positive, int n_min, double f_inc, double f_dec,
    double alpha_start, double f_alpha, double dt_max,
    const double* __restrict__ length_unit, double max_step, unsigned long long* __restrict__ error, int tile,
    unsigned long long step0, int steps)
{
    extern __shared__ double shared[];
    __shared__ int n_cand;
    __shared__ double control[3];   // keep, scale, step
    const int r = blockIdx.x, tid = threadIdx.x, stride = blockDim.x;
    const int v0 = vertex_start[r], v1 = vertex_start[r + 1], c0 = cell_start[r], c1 = cell_start[r + 1];
    const int nv = v1 - v0, nc = c1 - c0;
    const long base = v0 & ~31L;
    const int n_warps = (int)((v1 - base + 31) >> 5), rounds = (int)((v1 - base + stride - 1) / stride);
    // the arrays, offset so that global indices address them
    double* P = shared - 3L * v0;
    double* F = shared + 3L * nv - 3L * v0;
    double* V = shared + 6L * nv - 3L * v0;
    double* coef = shared + 9L * nv - 2L * c0;
    const int kept = Surface::directions ? nv : 0;
    double* inv = shared + 9L * nv + 2L * nc - v0;
    double* part = shared + 9L * nv + 2L * nc + kept;
    int* claim = (int*)(part + 3 * (n_warps + 1)) - c0;
    for (int j = tid; j < 3 * nv; j += stride) {
        shared[j] = pos[3L * v0 + j];
        shared[6L * nv + j] = vel[3L * v0 + j];
    }
    for (int c = c0 + tid; c < c1; c += stride) claim[c] = 0x7fffffff;
    if (tid == 0) n_cand = 0;
    const Surface::Size s = Surface::size(size, r);
    const bool running = fire_active[r], flipping = t1 && active[r];
    const FireParams fire = {n_min, f_inc, f_dec, alpha_start, f_alpha, dt_max};
    const TissueT1 t1_args = {chord2, new_length, length_factor, cand, cand_len, flips, refused, total_flips,
                              total_refused, step_need, log_count, log, logging, t1 ? *log_pass : 0};
    // thread 0 keeps the replica's dt, alpha and counter through the launch
    double replica_dt = dt[r], replica_alpha = alpha[r];
    long long positive = n_positive[r];
    const int lanes = tissue_cell_lanes(nc);
    const KeptNorm norm = {inv};
    __syncthreads();
    if (Surface::directions)
        for (int v = v0 + tid; v < v1; v += stride) inv[v] = RsqrtNorm()(P, v);
    __syncthreads();
    for (int step = 0; step < steps; ++step) {
        if (running) {
            tissue_cells<Surface>(P, norm, cell_vertices, sides, max_sides, s, nc, [=](int i) { return c0 + i; },
                                  lanes, kA, kP, A0, P0, coef, [](int) {});   // the vertex model (vertex_model.cuh)
            __syncthreads();
            for (int k = 0; k < rounds; ++k) {   // forces, and fire_reduce's terms F.v, v.v, F.F
                long g = base + tid + (long)k * stride;
                bool mine = g >= v0 && g < v1;
                double terms[3] = {0.0, 0.0, 0.0};
                if (mine) {
                    vec3 f = Surface::vertex_force(P, vn, vc, g, s, coef, NoExtra(), norm), w = load3(V, g);
                    store3(F, g, f);
                    terms[0] = dot3(f, w);
                    terms[1] = dot3(w, w);
                    terms[2] = dot3(f, f);
                }
                block_segment_warp<3>(terms, mine, g, v0, n_warps, part);
            }
            __syncthreads();
            if (tid < 32) {   // the sums, then the control (fire.cuh, as fire_reduce)
                double sums[3];
                block_segment_total<3>(part, v0, v1, n_warps, tile, sums);
                if (tid == 0)
                    fire_control_replica(sums[0], sums[1], sums[2], &replica_dt, &replica_alpha, &positive, fire,
                                         control, control + 1, control + 2);
            }
            __syncthreads();
            for (int v = v0 + tid; v < v1; v += stride) {   // fire_move's (fire.cuh)
                fire_move_vertex(P, V, F, v, s, control[0], control[1], control[2], length_unit[r], max_step,
                                 step0 + step, error);
                if (Surface::directions) inv[v] = RsqrtNorm()(P, v);
            }
        } else {
            for (int j = tid; j < 3 * nv; j += stride) shared[6L * nv + j] = 0.0;
        }
        __syncthreads();
        if (t1) {   // T1's pass of the next timestep
            tissue_t1_detect(P, vn, vc, s, r, v0, v1, v0, v1, flipping, t1_args, &n_cand, true);
            __syncthreads();
            tissue_t1_settle(P, vn, vc, cell_vertices, sides, max_sides, s, r, v0, v1, t1_args, claim, &n_cand,
                             step, [&](const int* e) {   // the flipped edge's norms; FIRE forgets its velocities
                               for (int k = 0; k < 3; k += 2) {   // with T1's reset_velocities (fire_reset_vertices)
                                   if (Surface::directions) inv[e[k]] = RsqrtNorm()(P, e[k]);
                                   if (reset_velocities) store3(V, e[k], v3(0.0, 0.0, 0.0));
                               }
                           });
            __syncthreads();
            if (tid == 0) n_cand = 0;   // every thread has read it: zero for the next pass
        }
    }
    for (int j = tid; j < 3 * nv; j += stride) {
        pos[3L * v0 + j] = shared[j];
        vel[3L * v0 + j] = shared[6L * nv + j];
    }
    if (tid == 0) { dt[r] = replica_dt; alpha[r] = replica_alpha; n_positive[r] = positive; }
}

// After tissue_steps, one thread: the table width the step-by-step path would hold (t1_apply grows it
// by one after each step in which a claimant's C3 or C4 row was full), the step_need slots set back
// to -1, and the flip log's pass number advanced by the steps' passes (t1_detect's count).
extern "C" __global__ void tissue_steps_finish(int* __restrict__ width, int* __restrict__ step_need, int steps,
                                              int* __restrict__ log_pass)
{
    if (blockIdx.x != 0 || threadIdx.x != 0) return;
    int w = *width;
    for (int j = 0; j < steps; ++j) {
        if (step_need[j] >= w) w += 1;
        step_need[j] = -1;
    }
    *width = w;
    *log_pass += steps;
}
