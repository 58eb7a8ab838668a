// Brownian and active dynamics: the CUDA path of brownian.py (same formulas and the same Philox
// draws, spherevm/random_philox.cuh), compiled once per surface (geometry/surface.cuh).
#include "geometry/surface.cuh"
#include "random_philox.cuh"

#define STREAM_BROWNIAN 0u
#define STREAM_ACTIVE 1u

// Carry director d to the tangent plane at the unit normal m (project, renormalise), then turn it
// about m by a Gaussian angle of standard deviation rot_amp (stream 1, counted by id).
__device__ vec3 transport_and_rotate(vec3 d, vec3 m, double rot_amp, unsigned int seed,
                                     unsigned long long timestep, unsigned int id)
{
    d = d - dot3(d, m) * m;
    d = normalize3(d);
    if (rot_amp > 0.0) {
        double t0, t1;
        svm_normal2(seed, STREAM_ACTIVE, timestep, id, 0u, &t0, &t1);
        double theta = rot_amp * t0;
        d = cos(theta) * d + sin(theta) * cross3(m, d);
    }
    return d;
}

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
    unsigned long long timestep = step0 + *step_add;
    int r = vertex_replica[i];
    vec3 x = load3(pos, i);
    vec3 n = Surface::normal(x);
    vec3 drift = mu * load3(forces, i);
    if (mode == 1) {
        vec3 p = load3(directors, vertex_cells[3 * i]) + load3(directors, vertex_cells[3 * i + 1]);
        p = p + load3(directors, vertex_cells[3 * i + 2]);
        p = v3(p.x / 3.0, p.y / 3.0, p.z / 3.0);
        p = p - dot3(p, n) * n;
        drift = drift + v0 * p;
    } else if (mode == 2) {
        drift = drift + v0 * load3(directors, i);
    }
    double z0, z1, z2, z3;
    svm_normal2(seed, STREAM_BROWNIAN, timestep, (unsigned int)i, 0u, &z0, &z1);
    svm_normal2(seed, STREAM_BROWNIAN, timestep, (unsigned int)i, 1u, &z2, &z3);
    double a = amp[r];
    vec3 w = dt * drift + v3(a * z0, a * z1, a * z2);
    vec3 dr = w - dot3(w, n) * n;
    double step = norm3(dr) / length_unit[r];
    if (!(step <= max_step)) {
        atomicMin(error, (timestep << 32) | (unsigned long long)i);
        return;
    }
    vec3 y = x + dr;
    vec3 m = Surface::normal(y);
    store3(pos, i, Surface::place(y, m, Surface::size(size, r)));
    if (mode == 2)
        store3(directors, i, transport_and_rotate(load3(directors, i), m, rot_amp, seed, timestep, (unsigned int)i));
}

// Cell directors after the move: transport to the tangent plane at the new cell centre, rotate.
extern "C" __global__ void active_cell_directors(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    double* __restrict__ directors, int n_cells, int max_sides, double rot_amp, unsigned int seed,
    unsigned long long step0, const unsigned long long* __restrict__ step_add)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    unsigned long long timestep = step0 + *step_add;
    vec3 m = Surface::cell_normal(pos, cell_vertices + c * max_sides, cell_sides[c]);
    store3(directors, c, transport_and_rotate(load3(directors, c), m, rot_amp, seed, timestep, (unsigned int)c));
}
