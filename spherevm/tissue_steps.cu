// Many Brownian steps of small tissues in one launch (spherevm/tissue_steps.py): a cluster of
// TISSUE_CLUSTER thread blocks per tissue (replica) runs `steps` whole steps, each T1's pass, the
// vertex model's forces and the Brownian move, with barriers between the phases and no launch,
// memset or host between the steps. The phases are limited by one SM's double-precision throughput
// (a 1,024-cell tissue's forces take about 20 us on one H200 SM), so a larger tissue spreads its
// cells and vertices over the cluster's blocks (Hopper thread block clusters): each block keeps a
// copy of the tissue's positions and cell coefficients in its shared memory and sends what it
// computes to the others' copies (distributed shared memory). T1's pass is cheap and runs in the
// cluster's first block; the tissue's topology stays in global memory.
// Every phase runs the same device function as the general kernels (vertex_model.cuh, t1_pass.cuh,
// brownian.cuh) on the same indices, so the trajectory is the general path's bit for bit: the same
// Philox draws (counted by global vertex index and timestep), the same flips (lowest edge index
// wins), the same arithmetic. Compiled once per surface and cluster size.
#include "plugins/forces/vertex_model.cuh"
#include "plugins/updaters/t1_pass.cuh"
#include "plugins/integrators/brownian.cuh"

#ifndef TISSUE_CLUSTER
#define TISSUE_CLUSTER 1
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
__device__ __forceinline__ double* cluster_map(double* p, unsigned int rank)
{
    unsigned long long out;
    asm volatile("mapa.u64 %0, %1, %2;" : "=l"(out) : "l"(p), "r"(rank));
    return (double*)out;
}
#else
#define TISSUE_CLUSTER_DIMS
__device__ __forceinline__ void cluster_sync() { __syncthreads(); }
__device__ __forceinline__ double* cluster_map(double* p, unsigned int) { return p; }
#endif

// x into item i of the array at `offset` (doubles, indexed as the tissue's copy is) in every other
// block's shared memory.
__device__ __forceinline__ void to_others(double* const* bases, int rank, long offset, long i, vec3 x)
{
    for (int q = 0; q < TISSUE_CLUSTER; ++q)
        if (q != rank) store3(bases[q] + offset, i, x);
}

// At most 1,024 threads a block (tissue_steps.THREADS). Shared memory of each block, in doubles (tissue_steps.py computes the same, in bytes): two copies
// of the positions (3 nv each: the step's, and the next, which the move writes while other blocks
// still read the step's), the cell coefficients (2 nc), the forces of the block's vertices
// (3 ceil(nv / TISSUE_CLUSTER)), then the T1 claims (nc ints).
// t1: 0 no T1 pass; else T1's parameters (chord2, new_length, length_factor), its candidate room (a
// slot per edge, the tissue's from 3 vertex_start[r] / 2 on), its per-pass counters (flips, refused:
// the last pass's are left, as t1_apply leaves them) and running totals, and step_need[j]: the widest
// C3/C4 row of a claimant in step j (tissue_steps_finish turns it into the width t1_apply grows).
extern "C" __global__ void __launch_bounds__(1024) TISSUE_CLUSTER_DIMS tissue_steps(
    double* __restrict__ pos, int* vn, int* vc, int* cell_vertices, int* sides,
    const int* __restrict__ vertex_start, const int* __restrict__ cell_start, const double* __restrict__ size,
    int max_sides, const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, int t1, const bool* __restrict__ active, const double* __restrict__ chord2,
    const double* __restrict__ new_length, double length_factor, int* cand, double* cand_len,
    int* __restrict__ flips, int* __restrict__ refused, unsigned long long* __restrict__ total_flips,
    unsigned long long* __restrict__ total_refused, int* __restrict__ step_need, const double* __restrict__ amp,
    const double* __restrict__ length_unit, double mu, double dt, double max_step, unsigned int seed,
    unsigned long long* __restrict__ error, unsigned long long step0, int steps)
{
    extern __shared__ double shared[];
    __shared__ int n_cand;
    __shared__ double* bases[TISSUE_CLUSTER];
    const int r = blockIdx.x / TISSUE_CLUSTER, rank = blockIdx.x % TISSUE_CLUSTER;   // a 1-D cluster's rank
    const int tid = threadIdx.x, stride = blockDim.x;
    const int v0 = vertex_start[r], v1 = vertex_start[r + 1], c0 = cell_start[r], c1 = cell_start[r + 1];
    const int nv = v1 - v0, nc = c1 - c0;
    const int vchunk = (nv + TISSUE_CLUSTER - 1) / TISSUE_CLUSTER, cchunk = (nc + TISSUE_CLUSTER - 1) / TISSUE_CLUSTER;
    const int vb0 = min(v1, v0 + rank * vchunk), vb1 = min(v1, vb0 + vchunk);   // this block's vertices
    const int cb0 = min(c1, c0 + rank * cchunk), cb1 = min(c1, cb0 + cchunk);   // and cells
    // the arrays, as offsets from a block's shared memory that global indices address
    const long at_pos[2] = {-3L * v0, 3L * nv - 3L * v0};
    const long at_coef = 6L * nv - 2L * c0;
    double* coef = shared + at_coef;
    double* F = shared + 6L * nv + 2L * nc - 3L * vb0;
    int* claim = (int*)(shared + 6L * nv + 2L * nc + 3L * vchunk) - c0;
    if (tid < TISSUE_CLUSTER) bases[tid] = cluster_map(shared, tid);
    for (int j = tid; j < 3 * nv; j += stride) shared[j] = pos[3L * v0 + j];
    for (int c = c0 + tid; c < c1; c += stride) claim[c] = 0x7fffffff;
    const Surface::Size s = Surface::size(size, r);
    const bool flipping = t1 && active[r];
    const int room0 = (3 * v0) / 2, room = (3 * v1) / 2 - room0;
    int* tcand = cand + (long)room0 * CAND_INTS;
    double* tlen = cand_len + room0;
    cluster_sync();   // every block of the cluster has started (its shared memory may be written)
    int now = 0;
    for (int step = 0; step < steps; ++step) {
        unsigned long long timestep = step0 + step;
        double* P = shared + at_pos[now];
        double* next = shared + at_pos[1 - now];
        if (t1) {   // T1's pass in the first block: detect, check and claim, apply (t1_pass.cuh)
            if (rank == 0) {
                if (tid == 0) { n_cand = 0; flips[r] = 0; refused[r] = 0; }
                __syncthreads();
                if (flipping)
                    for (int u = v0 + tid; u < v1; u += stride)
                        t1_detect_vertex(P, vn, vc, s, chord2[r], r, u, &n_cand, tcand, tlen, room);
                __syncthreads();
                int n = min(n_cand, room);
                for (int i = tid; i < n; i += stride) {
                    int* e = tcand + (long)i * CAND_INTS;
                    if (t1_check_candidate(P, vn, sides, cell_vertices, max_sides, s,
                                           t1_full_length(new_length[r], length_factor, tlen[i]), claim, e)) {
                        atomicMax(step_need + step, max(sides[e[9]], sides[e[10]]));
                    } else {
                        atomicAdd(refused + r, 1);
                        atomicAdd(total_refused + r, 1ull);
                    }
                }
                __syncthreads();
                for (int i = tid; i < n; i += stride) {
                    const int* e = tcand + (long)i * CAND_INTS;
                    if (t1_apply_candidate(P, vn, vc, cell_vertices, sides, max_sides, s,
                                           t1_full_length(new_length[r], length_factor, tlen[i]), claim, e)) {
                        atomicAdd(flips + r, 1);
                        atomicAdd(total_flips + r, 1ull);
                        to_others(bases, rank, at_pos[now], e[0], load3(P, e[0]));
                        to_others(bases, rank, at_pos[now], e[2], load3(P, e[2]));
                    }
                }
            }
            cluster_sync();   // the flips' topology and positions, everywhere
        }
        for (int c = cb0 + tid; c < cb1; c += stride) {   // the vertex model (vertex_model.cuh): this block's cells
            double A, Pc;
            Surface::cell_measures(P, cell_vertices + (long)c * max_sides, sides[c], s, &A, &Pc);
            vm_cell_terms(A, Pc, c, s, kA, kP, A0, P0, coef);
            for (int q = 0; q < TISSUE_CLUSTER; ++q)
                if (q != rank) {
                    bases[q][at_coef + 2L * c] = coef[2L * c];
                    bases[q][at_coef + 2L * c + 1] = coef[2L * c + 1];
                }
        }
        cluster_sync();
        for (int v = vb0 + tid; v < vb1; v += stride) {   // this block's vertices: force, then the move (brownian.cuh)
            store3(F, v, Surface::vertex_force(P, vn, vc, v, s, coef));
            store3(next, v, load3(P, v));
            brownian_vertex(next, F, v, vc, s, amp[r], length_unit[r], nullptr, 0, mu, dt, 0.0, 0.0, max_step, seed,
                            timestep, error);
            to_others(bases, rank, at_pos[1 - now], v, load3(next, v));
        }
        cluster_sync();
        now = 1 - now;
    }
    for (int j = 3 * (vb0 - v0) + tid; j < 3 * (vb1 - v0); j += stride) pos[3L * v0 + j] = shared[at_pos[now] + 3L * v0 + j];
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
