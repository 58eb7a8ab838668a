#ifndef TISSUE_THREADS
#define TISSUE_THREADS 1024
#endif

// Many Brownian steps of small tissues in one launch (spherevm/tissue_steps.py): one thread block per
// tissue (replica) runs `steps` whole steps, each T1's pass, the vertex model's forces and the
// Brownian move, with barriers between the phases and no launch, memset or host between the steps.
// The tissue's positions, forces, cell coefficients and T1 claims live in the block's shared memory
// for the whole launch; its topology stays in global memory (written by its own block only, read
// through the SM's L1). Every phase runs the same device function as the general kernels
// (vertex_model.cuh, t1_pass.cuh, brownian.cuh) on the same indices, so the trajectory is the
// general path's bit for bit: the same Philox draws (counted by global vertex index and timestep),
// the same flips (lowest edge index wins), the same arithmetic. Compiled once per surface.
#include "plugins/forces/vertex_model.cuh"
#include "plugins/updaters/t1_pass.cuh"
#include "plugins/integrators/brownian.cuh"

// Shared memory of a tissue of nv vertices and nc cells, in bytes (tissue_steps.py computes the same):
// positions and forces (3 nv doubles each), coefficients (2 nc doubles), claims (nc ints).
// t1: 0 no T1 pass; else T1's parameters (chord2, new_length, length_factor), its candidate room (a
// slot per edge, the tissue's from 3 vertex_start[r] / 2 on), its per-pass counters (flips, refused:
// the last pass's are left, as t1_apply leaves them) and running totals, and step_need[j]: the widest
// C3/C4 row of a claimant in step j (tissue_steps_finish turns it into the width t1_apply grows).
extern "C" __global__ void __launch_bounds__(TISSUE_THREADS) tissue_steps(
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
    const int r = blockIdx.x, tid = threadIdx.x, stride = blockDim.x;
    const int v0 = vertex_start[r], v1 = vertex_start[r + 1], c0 = cell_start[r], c1 = cell_start[r + 1];
    const int nv = v1 - v0, nc = c1 - c0;
    // the tissue's arrays, offset so that global indices address them
    double* P = shared - 3L * v0;
    double* F = shared + 3L * nv - 3L * v0;
    double* coef = shared + 6L * nv - 2L * c0;
    int* claim = (int*)(shared + 6L * nv + 2L * nc) - c0;
    for (int j = tid; j < 3 * nv; j += stride) shared[j] = pos[3L * v0 + j];
    for (int c = c0 + tid; c < c1; c += stride) claim[c] = 0x7fffffff;
    const Surface::Size s = Surface::size(size, r);
    const bool flipping = t1 && active[r];
    const int room0 = (3 * v0) / 2, room = (3 * v1) / 2 - room0;
    int* tcand = cand + (long)room0 * CAND_INTS;
    double* tlen = cand_len + room0;
    __syncthreads();
    for (int step = 0; step < steps; ++step) {
        unsigned long long timestep = step0 + step;
        if (t1) {   // T1's pass: detect, check and claim, apply (t1_pass.cuh)
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
                }
            }
            __syncthreads();
        }
        for (int c = c0 + tid; c < c1; c += stride) {   // the vertex model (vertex_model.cuh)
            double A, Pc;
            Surface::cell_measures(P, cell_vertices + (long)c * max_sides, sides[c], s, &A, &Pc);
            vm_cell_terms(A, Pc, c, s, kA, kP, A0, P0, coef);
        }
        __syncthreads();
        for (int v = v0 + tid; v < v1; v += stride) store3(F, v, Surface::vertex_force(P, vn, vc, v, s, coef));
        __syncthreads();
        for (int v = v0 + tid; v < v1; v += stride)     // the move (brownian.cuh)
            brownian_vertex(P, F, v, vc, s, amp[r], length_unit[r], nullptr, 0, mu, dt, 0.0, 0.0, max_step, seed,
                            timestep, error);
        __syncthreads();
    }
    for (int j = tid; j < 3 * nv; j += stride) pos[3L * v0 + j] = shared[j];
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
