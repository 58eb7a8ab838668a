// Brownian and active dynamics' stage of the fused small-tissue steps (spherevm/tissue_steps.cu,
// Brownian.fused_stage): a vertex's move (brownian_vertex) and, with cell directors (MODE 1), each
// cell's director carried to its new normal and turned (transport_and_rotate), the functions of
// brownian.cu's kernels, so the fused moves are theirs bit for bit. BrownianArgs is declared from
// its Python definition (Brownian.FUSED_ARGS). MODE: 0 no self-propulsion, 1 cell directors,
// 2 vertex directors.
#pragma once
#include "plugins/integrators/brownian.cuh"

template <int MODE>
struct BrownianStage {
    static constexpr bool minimizer = false;
    static constexpr bool cell_phase = MODE == 1;   // the cells' directors after every move
    BrownianArgs a;

    // Vertex v of replica r (next: the positions it moves in; F: its force), at `timestep`.
    __device__ __forceinline__ void vertex(double* next, const double* F, long v, const int* vc, Surface::Size s,
                                           int r, unsigned long long timestep) const
    {
        brownian_vertex(next, F, v, vc, s, a.amp[r], a.length_unit[r], a.directors, MODE, a.mu, a.dt, a.v0,
                        a.rot_amp, a.max_step, a.seed, timestep, a.error);
    }

    // Cell c's director, after every vertex moved (pos: the new positions), as active_cell_directors.
    __device__ __forceinline__ void cell(const double* pos, const int* cell_vertices, const int* sides, int max_sides,
                                         long c, Surface::Size s, unsigned long long timestep) const
    {
        vec3 m = Surface::cell_normal(pos, cell_vertices + c * max_sides, sides[c], s);
        store3(a.directors, c, transport_and_rotate(load3(a.directors, c), m, a.rot_amp, a.seed, timestep,
                                                    (unsigned int)c));
    }

    __device__ __forceinline__ void reset_vertex(double*, long) const {}
};
