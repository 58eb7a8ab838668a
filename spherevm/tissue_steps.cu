// Many steps of small tissues in one launch (spherevm/tissue_steps.py): a cluster of TISSUE_CLUSTER
// thread blocks per tissue (replica) runs `steps` whole cycles of the plan (spherevm/plan.py), with
// barriers between the phases and no launch, memset or host between the steps. The kernels here
// are templates over the operations' stages (Operation.fused_stage): Forces, the forces' stages
// together (each a cell part, whose coefficients the tissue keeps in shared memory, and a vertex
// part, summed in the operations' order); Move, the integrator's stage; Pass, the updater's stage
// (T1's pass) or NoPass. tissue_steps.py assembles the source: the argument structs (TissueState and
// each stage's, declared from their Python definitions), the shared-memory layouts (likewise),
// this file, the stages' headers, the Forces aggregate and the extern "C" kernels instantiating the
// templates. Every stage calls the functions of its operation's general kernels on the same global
// indices, so the trajectory is the general path's bit for bit: the same Philox draws (counted by
// global vertex index and timestep), the same flips (lowest edge index wins), the same arithmetic.
//
// The phases are limited by one SM's double-precision throughput (a 1,024-cell tissue's forces take
// about 20 us on one H200 SM), so a larger tissue spreads its cells and vertices over the cluster's
// blocks (Hopper thread block clusters): each block keeps a copy of the tissue's positions and cell
// coefficients in its shared memory and sends what it computes to the others' copies (distributed
// shared memory). T1's pass is cheap and runs in the cluster's first block; the tissue's topology
// stays in global memory. On the sphere each block also keeps every vertex's 1 / |x| (KeptNorm,
// geometry/surface.cuh), computed once after each move or flip.
#pragma once
#include "geometry/surface.cuh"
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

// The forces' cell parts (Forces::cell: the vertex model's vm_cell_terms, ...) of `count` cells,
// cell(0) .. cell(count - 1), by the calling block, from each cell's area and perimeter, the
// vertices' directions from norm (Surface::directions), and the cell's vertices; the coefficients
// go to the stages' regions of `data` (the tissue's coefficient area: nc cells from c0); sent(c)
// after each. On a surface that splits a cell's corners (the sphere: Surface::split_corners), a
// cell takes `lanes` neighbouring threads (a power of two, at most 8): each lane computes every
// lanes-th corner's arc and fan factor (Surface::cell_corner), and every lane adds them in the
// cell's order (Surface::add_corner), so the chain of a cell's atan2s is shortened and the bits are
// cell_measures' whatever the lanes. Every thread of the block calls it, with S = Surface.
template <class S, class Forces, class Cell, class Sent>
__device__ __forceinline__ void tissue_cells(const double* P, KeptNorm norm, const int* cell_vertices,
                                             const int* sides, int max_sides, typename S::Size s, int count,
                                             Cell cell, int lanes, const Forces& forces, double* data, long nc,
                                             long c0, Sent sent)
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
                    forces.cell(A, Pc, c, s, data, nc, c0, P, row, n);
                    sent(c);
                }
            }
            return;
        }
    }
    for (int i = tid; i < count; i += stride) {   // one thread a cell
        const int c = cell(i);
        const int* row = cell_vertices + (long)c * max_sides;
        double A, Pc;
        S::cell_measures(P, row, sides[c], s, &A, &Pc, norm);
        forces.cell(A, Pc, c, s, data, nc, c0, P, row, sides[c]);
        sent(c);
    }
}

// Threads a cell in tissue_cells (cb cells): as many as a block of at most 512 threads has for its
// cells, a power of two up to 8. A block of more threads keeps one a cell: its SM is busy with its
// many warps, and the lanes' shuffles and repeated sums only add work (one H200: 8 x 1,024 cells on
// 2 blocks of 1,024 threads, 18 % longer on two lanes a cell; on 4 blocks of 512 threads, 6 %
// shorter with the kept norms; 1,024 x 32 and 64 x 64 cells, 2-5 warps a block, 4-14 % shorter).
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

// No updater in the steps: a pass that finds nothing.
struct NoPass {
    static constexpr bool present = false;
    __device__ NoPass(const NoPassArgs&, int*) {}
    __device__ __forceinline__ bool resets_vertices() const { return false; }
    __device__ __forceinline__ void detect(const double*, const int*, const int*, Surface::Size, int, int, int, int,
                                           int, bool, int*, bool) const {}
    template <class Flipped>
    __device__ __forceinline__ void settle(double*, int*, int*, int*, int*, int, Surface::Size, int, int, int, int*,
                                           int*, int, Flipped) const {}
    __device__ __forceinline__ int flipped_cell(int, int) const { return 0; }
    __device__ __forceinline__ int index(const int*) const { return 0; }
};

// A force stage joined into another's vertex force (FusedStage.extra, Force.fused_combined): the
// Extra's add_gradient (plugins/forces/vertex_model.cuh; Surface::vertex_force) through which the
// other stage's vertex force adds the joined stage's gradient before its projection, as the pair's
// general kernels do.
template <class Stage>
struct StageExtra {
    const Stage& stage;
    const double* coef;   // the joined stage's regions
    const double* more;
    __device__ __forceinline__ void add_gradient(vec3& g, const double* pos, const int* vn, const int* vc, long v,
                                                 vec3 x) const
    {
        stage.add_gradient(g, pos, vn, vc, v, x, coef, more);
    }
};

// The forces' neighbour parts (Forces::neighbours: a second per-cell part, which may read any cell's
// coefficients) of the cells cells(i), i < count, by the calling block, into the stages' regions of
// `more`.
template <class Forces, class Cells>
__device__ __forceinline__ void tissue_neighbours(const Forces& forces, const TissueState& st, const double* P,
                                                  Surface::Size s, int count, Cells cells, const double* data,
                                                  double* more, long nc, long c0)
{
    for (int i = threadIdx.x; i < count; i += blockDim.x)
        forces.neighbours(P, st.vc, st.cell_vertices, st.sides, st.max_sides, cells(i), s, data, more, nc, c0);
}

// The steps of run (Plan.device_cycle: update, integrate). At most TISSUE_THREADS threads a block
// (tissue_steps.layout's bound). Shared memory of each block: TissueStepLayout (tissue_steps.py's
// STEP_LAYOUT, its one definition): two copies of the positions (3 nv each: the step's, and the
// next, which the move writes while other blocks still read the step's), the forces' cell
// coefficients (Forces::cell_doubles a cell) and neighbour parts (Forces::neighbour_doubles a
// cell), on the sphere two copies of the kept 1 / |x| (nv each, as the positions), the forces of
// the block's vertices (3 ceil(nv / TISSUE_CLUSTER)), then the pass's claims (nc ints) and flips
// (ceil(nc / 4) ints), and where a force has a neighbour part the step at which each cell was last
// needed and the cells a step needs (nc ints each).
//
// A step: every block lists the short edges of its vertices and computes its cells' coefficients on
// the step's positions (a barrier); if any edge is short, the first block checks and flips them and
// computes again the four cells of each flip (a flip moves and re-links only its four cells, and the
// flips of a pass share no cell: T1's claims), then a barrier; where a force has a neighbour part
// (Forces::neighbours, read from every cell's coefficients: the bending force's), every block
// computes those of the cells of its own vertices, the only ones its vertex forces read (about 300
// of 1,024 on a block of 512 vertices numbered as a tiling numbers them), on the cells after the
// flips: no sending to the other blocks and no cluster barrier; then the forces and the move of
// every block's vertices (a barrier). Where the move has a cell part (active cell directors), every block
// does its cells' part of a step's move with the next step's first phase (on the positions before
// that step's flips, as the general path does it) and after the last step. The cells are those the
// general path computes after T1's pass, with two or three barriers a step instead of four.
template <class Forces, class Move, class Pass>
__device__ __forceinline__ void tissue_steps_body(const TissueState& st, const Forces& forces, const Move& move,
                                                  const Pass& pass, unsigned long long step0, int steps)
{
    extern __shared__ double shared[];
    __shared__ int n_cand, n_flipped, n_needed;
    __shared__ double* bases[TISSUE_CLUSTER];
    const int r = blockIdx.x / TISSUE_CLUSTER, rank = blockIdx.x % TISSUE_CLUSTER;   // a 1-D cluster's rank
    const int tid = threadIdx.x, stride = blockDim.x;
    const int v0 = st.vertex_start[r], v1 = st.vertex_start[r + 1], c0 = st.cell_start[r], c1 = st.cell_start[r + 1];
    const int nv = v1 - v0, nc = c1 - c0;
    const int vchunk = (nv + TISSUE_CLUSTER - 1) / TISSUE_CLUSTER, cchunk = (nc + TISSUE_CLUSTER - 1) / TISSUE_CLUSTER;
    const int vb0 = min(v1, v0 + rank * vchunk), vb1 = min(v1, vb0 + vchunk);   // this block's vertices
    const int cb0 = min(c1, c0 + rank * cchunk), cb1 = min(c1, cb0 + cchunk);   // and cells
    const int kept = Surface::directions ? nv : 0;
    const TissueStepLayout at = tissue_step_layout(nv, nc, kept, vchunk, Forces::cell_doubles,
                                                   Forces::neighbour_doubles);
    // the arrays, as offsets from a block's shared memory that global indices address (copy k of the
    // positions at at_pos + 3 nv k, of the kept norms at at_inv + kept k: scalars, not arrays that a
    // step's index would leave in local memory)
    const long at_pos = at.pos - 3L * v0;
    const long at_inv = at.inv - v0;
    double* coef = shared + at.coef;   // the coefficient area: each force stage's region (Forces::cell)
    double* more = shared + at.more;   // and of the neighbour parts (Forces::neighbours)
    double* F = shared + at.force - 3L * vb0;
    int* claim = (int*)(shared + at.ints) + at.claim - c0;
    int* flipped = (int*)(shared + at.ints) + at.flipped;   // the first block's: the candidates its pass flipped
    int* mark = (int*)(shared + at.ints) + at.mark - c0;     // the step at which a cell was last needed
    int* needed = (int*)(shared + at.ints) + at.needed;      // the cells this block's vertices need
    if (tid < TISSUE_CLUSTER) bases[tid] = cluster_map(shared, tid);
    if (tid == 0) { n_cand = 0; n_flipped = 0; n_needed = 0; }
    int* const count = cluster_map(&n_cand, 0);   // the first block's
    for (int j = tid; j < 3 * nv; j += stride) shared[at.pos + j] = st.pos[3L * v0 + j];
    __syncthreads();
    if (Surface::directions)
        for (int v = v0 + tid; v < v1; v += stride) shared[at_inv + v] = RsqrtNorm()(shared + at_pos, v);
    for (int c = c0 + tid; c < c1; c += stride) claim[c] = 0x7fffffff;
    if constexpr (Forces::neighbour_doubles > 0)
        for (int c = c0 + tid; c < c1; c += stride) mark[c] = -1;
    const Surface::Size s = Surface::size(st.size, r);
    const bool flipping = Pass::present && st.active[r];
    const int lanes = tissue_cell_lanes(cb1 - cb0);
    auto send = [&](int c) {   // a cell's coefficients to the other blocks
        for (int q = 0; q < TISSUE_CLUSTER; ++q)
            if (q != rank) Forces::copy_cell(c, coef, bases[q] + at.coef, nc, c0);
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
        if (Pass::present)   // the pass begins: every block lists the short edges of its vertices
            pass.detect(P, st.vn, st.vc, s, r, vb0, vb1, v0, v1, flipping, count, rank == 0);
        if constexpr (Move::cell_phase)   // the last step's move, its cell part (active cell directors)
            if (step > 0)
                for (int c = cb0 + tid; c < cb1; c += stride)
                    move.cell(P, st.cell_vertices, st.sides, st.max_sides, c, s, timestep - 1);
        if constexpr (Forces::measures)   // this block's cells, their coefficients to the other blocks
            tissue_cells<Surface>(P, norm, st.cell_vertices, st.sides, st.max_sides, s, cb1 - cb0,
                                  [=](int i) { return cb0 + i; }, lanes, forces, coef, nc, c0, send);
        cluster_sync();   // the candidates listed, the coefficients everywhere
        if (Pass::present && *count > 0) {   // (the same in every block) the pass's check and flips, in the first block
            if (rank == 0) {
                pass.settle(P, st.vn, st.vc, st.cell_vertices, st.sides, st.max_sides, s, r, v0, v1, claim, &n_cand,
                            step, [&](const int* e) {   // the flipped edge, everywhere
                                for (int k = 0; k < 3; k += 2) {
                                    to_others(bases, rank, pos_now, e[k], load3(P, e[k]));
                                    keep_norm(bases, inv_now, P, e[k]);
                                }
                                flipped[atomicAdd(&n_flipped, 1)] = pass.index(e);
                            });
                __syncthreads();   // every flip applied and listed: its four cells (C1..C4) again
                const int fixes = 4 * n_flipped;
                auto fixed = [&](int i) { return pass.flipped_cell(flipped[i >> 2], i & 3); };
                if constexpr (Forces::measures)
                    tissue_cells<Surface>(P, norm, st.cell_vertices, st.sides, st.max_sides, s, fixes, fixed,
                                          tissue_cell_lanes(fixes), forces, coef, nc, c0, send);
            }
            cluster_sync();   // the flips and their cells everywhere; every block has read the count
            if (rank == 0 && tid == 0) { n_cand = 0; n_flipped = 0; }
        }
        if constexpr (Forces::neighbour_doubles > 0) {   // the neighbour parts of the cells of this block's vertices
            for (int v = vb0 + tid; v < vb1; v += stride)
                for (int k = 0; k < 3; ++k) {
                    const int c = st.vc[3L * v + k];
                    if (atomicExch(&mark[c], step) != step) needed[atomicAdd(&n_needed, 1)] = c;
                }
            __syncthreads();
            tissue_neighbours(forces, st, P, s, n_needed, [=](int i) { return needed[i]; }, coef, more, nc, c0);
            __syncthreads();
            if (tid == 0) n_needed = 0;   // (read again after the step's last barrier)
        }
        for (int v = vb0 + tid; v < vb1; v += stride) {   // this block's vertices: force, then the move
            store3(F, v, forces.vertex(P, st.vn, st.vc, v, s, coef, more, nc, c0, norm));
            store3(next, v, load3(P, v));
            move.vertex(next, F, v, st.vc, s, r, timestep);
            to_others(bases, rank, pos_next, v, load3(next, v));
            keep_norm(bases, inv_next, next, v);
        }
        cluster_sync();
        now = 1 - now;
    }
    if constexpr (Move::cell_phase)   // the last step's cell part, on its new positions
        if (steps > 0)
            for (int c = cb0 + tid; c < cb1; c += stride)
                move.cell(shared + at_pos + 3L * nv * now, st.cell_vertices, st.sides, st.max_sides, c, s,
                          step0 + steps - 1);
    for (int j = 3 * (vb0 - v0) + tid; j < 3 * (vb1 - v0); j += stride)
        st.pos[3L * v0 + j] = shared[at_pos + 3L * nv * now + 3L * v0 + j];
}

// The iterations of minimize (Plan.device_cycle: integrate, update), a thread block per tissue: each
// iteration the forces, the minimiser's per-replica sums (in device_common.cuh's order for a launch
// of `tile` threads a block: block_segment_warp / block_segment_total), its control (thread 0) and
// move, then the pass of the next timestep, as minimize orders them. A stopped replica (st.active
// false) only has its vertex state (velocities) zeroed (and the pass's counters, as each pass does).
// Shared memory: TissueMinimizeLayout (tissue_steps.py's MINIMIZE_LAYOUT): the positions, forces
// and the minimiser's vertex state (3 nv each), the forces' cell coefficients and neighbour parts (after
// the cell coefficients, a barrier between), on the sphere the kept
// 1 / |x| (nv, KeptNorm: after each move and flip), the sums' warp parts (n_sums (n_warps + 1),
// n_warps the warps from v0 & ~31 to v1), then the pass's claims (nc ints).
template <class Forces, class Move, class Pass>
__device__ __forceinline__ void tissue_minimize_body(const TissueState& st, const Forces& forces, const Move& move,
                                                     const Pass& pass, int tile, unsigned long long step0, int steps)
{
    extern __shared__ double shared[];
    __shared__ int n_cand;
    __shared__ double control[3];   // the control's output (FIRE: keep, scale, step)
    const int r = blockIdx.x, tid = threadIdx.x, stride = blockDim.x;
    const int v0 = st.vertex_start[r], v1 = st.vertex_start[r + 1], c0 = st.cell_start[r], c1 = st.cell_start[r + 1];
    const int nv = v1 - v0, nc = c1 - c0;
    const long base = v0 & ~31L;
    const int n_warps = (int)((v1 - base + 31) >> 5), rounds = (int)((v1 - base + stride - 1) / stride);
    const int kept = Surface::directions ? nv : 0;
    const TissueMinimizeLayout at = tissue_minimize_layout(nv, nc, kept, n_warps, Forces::cell_doubles,
                                                             Forces::neighbour_doubles, Move::n_sums,
                                                             Move::vertex_doubles);
    // the arrays, offset so that global indices address them
    double* P = shared + at.pos - 3L * v0;
    double* F = shared + at.force - 3L * v0;
    double* V = shared + at.velocity - 3L * v0;
    double* coef = shared + at.coef;
    double* more = shared + at.more;
    double* inv = shared + at.inv - v0;
    double* part = shared + at.part;
    int* claim = (int*)(shared + at.ints) + at.claim - c0;
    double* vel = move.vertex_state();
    for (int j = tid; j < 3 * nv; j += stride) {
        shared[at.pos + j] = st.pos[3L * v0 + j];
        shared[at.velocity + j] = vel[3L * v0 + j];
    }
    for (int c = c0 + tid; c < c1; c += stride) claim[c] = 0x7fffffff;
    if (tid == 0) n_cand = 0;
    const Surface::Size s = Surface::size(st.size, r);
    const bool running = st.active[r], flipping = Pass::present && st.active[r];
    typename Move::Control ctl = move.load(r);   // thread 0's through the launch
    const int lanes = tissue_cell_lanes(nc);
    const KeptNorm norm = {inv};
    __syncthreads();
    if (Surface::directions)
        for (int v = v0 + tid; v < v1; v += stride) inv[v] = RsqrtNorm()(P, v);
    __syncthreads();
    for (int step = 0; step < steps; ++step) {
        if (running) {
            if constexpr (Forces::measures)
                tissue_cells<Surface>(P, norm, st.cell_vertices, st.sides, st.max_sides, s, nc,
                                      [=](int i) { return c0 + i; }, lanes, forces, coef, nc, c0, [](int) {});
            __syncthreads();
            if constexpr (Forces::neighbour_doubles > 0) {
                tissue_neighbours(forces, st, P, s, nc, [=](int i) { return c0 + i; }, coef, more, nc, c0);
                __syncthreads();
            }
            for (int k = 0; k < rounds; ++k) {   // forces, and the terms of the sums
                long g = base + tid + (long)k * stride;
                bool mine = g >= v0 && g < v1;
                double terms[Move::n_sums] = {};
                if (mine) {
                    vec3 f = forces.vertex(P, st.vn, st.vc, g, s, coef, more, nc, c0, norm);
                    store3(F, g, f);
                    move.terms(f, load3(V, g), terms);
                }
                block_segment_warp<Move::n_sums>(terms, mine, g, v0, n_warps, part);
            }
            __syncthreads();
            if (tid < 32) {   // the sums, then the control
                double sums[Move::n_sums];
                block_segment_total<Move::n_sums>(part, v0, v1, n_warps, tile, sums);
                if (tid == 0) move.control(sums, &ctl, control);
            }
            __syncthreads();
            for (int v = v0 + tid; v < v1; v += stride) {   // the move
                move.vertex(P, V, F, v, s, r, control, step0 + step);
                if (Surface::directions) inv[v] = RsqrtNorm()(P, v);
            }
        } else {
            for (int j = tid; j < 3 * nv; j += stride) shared[at.velocity + j] = 0.0;
        }
        __syncthreads();
        if (Pass::present) {   // the pass of the next timestep
            pass.detect(P, st.vn, st.vc, s, r, v0, v1, v0, v1, flipping, &n_cand, true);
            __syncthreads();
            pass.settle(P, st.vn, st.vc, st.cell_vertices, st.sides, st.max_sides, s, r, v0, v1, claim, &n_cand, step,
                        [&](const int* e) {   // the flipped edge's norms; the minimiser forgets their motion
                            for (int k = 0; k < 3; k += 2) {   // where the pass asks (T1's reset_velocities)
                                if (Surface::directions) inv[e[k]] = RsqrtNorm()(P, e[k]);
                                if (pass.resets_vertices()) move.reset_vertex(V, e[k]);
                            }
                        });
            __syncthreads();
            if (tid == 0) n_cand = 0;   // every thread has read it: zero for the next pass
        }
    }
    for (int j = tid; j < 3 * nv; j += stride) {
        st.pos[3L * v0 + j] = shared[at.pos + j];
        vel[3L * v0 + j] = shared[at.velocity + j];
    }
    if (tid == 0) move.store(r, ctl);
}
