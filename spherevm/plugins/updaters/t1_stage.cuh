// T1's stage of the fused small-tissue steps (spherevm/tissue_steps.cu, T1.fused_stage): a tissue's
// pass in two parts with a barrier between, t1_pass.cuh's functions on the general kernels' global
// indices, so the flips are the general path's. T1StageArgs is declared from its Python definition
// (T1.FUSED_ARGS): the parameters (chord2, new_length, length_factor, untangle), the candidate room
// (a slot per edge, the tissue's from 3 vertex_start[r] / 2 on), the per-pass counters (flips,
// refused: the last pass's are left, as t1_apply leaves them) and running totals, the flip log
// (logging; log_pass: its pass count before the launch) and whether the integrator forgets the
// flipped vertices' motion (reset_vertices).
#pragma once
#include "plugins/updaters/t1_pass.cuh"

struct T1Stage {
    static constexpr bool present = true;
    T1StageArgs a;
    int pass0;          // the number of the launch's first pass less one, as t1_detect counts
    int* step_need;     // per step of the launch: the widest C3/C4 row of a claimant (tissue_steps_finish)

    __device__ T1Stage(const T1StageArgs& args, int* need) : a(args), pass0(*args.log_pass), step_need(need) {}

    __device__ __forceinline__ bool resets_vertices() const { return a.reset_vertices != 0; }

    // The pass begins: the short edges of vertices vb0..vb1 of tissue r (vertices v0..v1) into the
    // tissue's candidate room (every block of the tissue its own); the settling block zeroes the
    // pass's counters. n_cand: the tissue's candidate count (in the settling block's shared memory).
    __device__ __forceinline__ void detect(const double* P, const int* vn, const int* vc, Surface::Size s, int r,
                                           int vb0, int vb1, int v0, int v1, bool flipping, int* n_cand,
                                           bool settling) const
    {
        const int room0 = (3 * v0) / 2, room = (3 * v1) / 2 - room0;
        if (settling && threadIdx.x == 0) { a.flips[r] = 0; a.refused[r] = 0; }
        if (flipping)
            for (int u = vb0 + threadIdx.x; u < vb1; u += blockDim.x)
                t1_detect_vertex(P, vn, vc, s, a.chord2[r], a.untangle != 0, r, u, n_cand,
                                 a.cand + (long)room0 * CAND_INTS, a.cand_len + room0, room);
    }

    // The candidates checked and claimed (a warp a candidate: t1_check_candidate_warp) and applied,
    // in one block; flipped(e) after each flip. claim: the tissue's claims (all free between passes);
    // step: the pass's place in the launch.
    template <class Flipped>
    __device__ __forceinline__ void settle(double* P, int* vn, int* vc, int* cell_vertices, int* sides, int max_sides,
                                           Surface::Size s, int r, int v0, int v1, int* claim, int* n_cand, int step,
                                           Flipped flipped) const
    {
        const int tid = threadIdx.x, stride = blockDim.x;
        const int room0 = (3 * v0) / 2, room = (3 * v1) / 2 - room0;
        int* cand = a.cand + (long)room0 * CAND_INTS;
        double* len = a.cand_len + room0;
        const int n = min(*n_cand, room);
        for (int i = tid >> 5; i < n; i += stride >> 5) {   // a warp a candidate (blockDim.x: a multiple of 32)
            int* e = cand + (long)i * CAND_INTS;
            bool kept = t1_check_candidate_warp(P, vn, sides, cell_vertices, max_sides, s,
                                                t1_full_length(a.new_length[r], a.length_factor, len[i]),
                                                a.untangle != 0, claim, e);
            if ((tid & 31) != 0) continue;
            if (kept) {
                atomicMax(step_need + step, max(sides[e[9]], sides[e[10]]));
            } else {
                atomicAdd(a.refused + r, 1);
                atomicAdd(a.total_refused + r, 1ull);
            }
        }
        __syncthreads();
        for (int i = tid; i < n; i += stride) {
            const int* e = cand + (long)i * CAND_INTS;
            if (t1_apply_candidate(P, vn, vc, cell_vertices, sides, max_sides, s,
                                   t1_full_length(a.new_length[r], a.length_factor, len[i]), claim, e)) {
                atomicAdd(a.flips + r, 1);
                atomicAdd(a.total_flips + r, 1ull);
                if (a.logging) t1_log_flip(a.log_count, a.log, pass0 + step + 1, e);
                flipped(e);
            }
        }
    }

    // Cell k (0..3: C1..C4) of candidate i, whose four cells a flip moves and re-links.
    __device__ __forceinline__ int flipped_cell(int i, int k) const { return a.cand[(long)i * CAND_INTS + 7 + k]; }

    // The index in the candidate room of candidate e.
    __device__ __forceinline__ int index(const int* e) const { return (int)((e - a.cand) / CAND_INTS); }
};

// After a launch of the fused steps (tissue_steps, tissue_minimize), one thread: the table width the
// step-by-step path would hold (t1_apply grows it by one after each step in which a claimant's C3 or
// C4 row was full), the step_need slots set back to -1, and the flip log's pass number advanced by
// the steps' passes (t1_detect's count).
extern "C" __global__ void t1_steps_finish(int* __restrict__ width, int* __restrict__ step_need, int steps,
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
