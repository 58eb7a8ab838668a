// Brownian and active dynamics: the CUDA path of brownian.py (same formulas and the same Philox
// draws, spherevm/random_philox.cuh), compiled once per surface (geometry/surface.cuh). The move
// itself is brownian.cuh's, shared with the fused small-tissue steps.
#include "plugins/integrators/brownian.cuh"

// mode: 0 no self-propulsion, 1 cell directors, 2 vertex directors. size: the State's radius or box.
// The timestep is step0 + *step_add (Simulation.kernel_timestep: inside a CUDA graph it lives on the device).
// error: earliest (timestep << 32 | vertex) whose step was not finite or above max_step.
extern "C" __global__ void brownian_move(
    double* __restrict__ pos, const double* __restrict__ forces, const int* __restrict__ vertex_replica,
    const int* __restrict__ vertex_cells, const double* __restrict__ size, const double* __restrict__ amp,
    const double* __restrict__ length_unit, double* __restrict__ directors, int mode, double mu, double dt,
    double v0, double rot_amp, double max_step, unsigned int seed, unsigned long long step0,
    const unsigned long long* __restrict__ step_add, int n_vertices, unsigned long long* __restrict__ error)
{
    long i = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n_vertices) return;
    int r = vertex_replica[i];
    brownian_vertex(pos, forces, i, vertex_cells, Surface::size(size, r), amp[r], length_unit[r], directors, mode,
                    mu, dt, v0, rot_amp, max_step, seed, step0 + *step_add, error);
}

// Cell directors after the move: transport to the tangent plane at the new cell centre, rotate.
extern "C" __global__ void active_cell_directors(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    double* __restrict__ directors, int n_cells, int max_sides, double rot_amp, unsigned int seed,
    unsigned long long step0, const unsigned long long* __restrict__ step_add, const int* __restrict__ cell_replica,
    const double* __restrict__ size)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    unsigned long long timestep = step0 + *step_add;
    vec3 m = Surface::cell_normal(pos, cell_vertices + c * max_sides, cell_sides[c], Surface::size(size, cell_replica[c]));
    store3(directors, c, transport_and_rotate(load3(directors, c), m, rot_amp, seed, timestep, (unsigned int)c));
}
