// One vertex's Brownian (or active) move: the body of brownian.cu's kernel and of the fused small-tissue
// steps (spherevm/tissue_steps.cu), so both give the same bits. Compiled once per surface
// (geometry/surface.cuh); the Philox draws are counted by the vertex's global index.
#pragma once
#include "geometry/surface.cuh"
#include "random_philox.cuh"

#define STREAM_BROWNIAN 0u
#define STREAM_ACTIVE 1u

// Carry director d to the tangent plane at the unit normal m (project, renormalise), then turn it
// about m by a Gaussian angle of standard deviation rot_amp (stream 1, counted by id).
__device__ __forceinline__ vec3 transport_and_rotate(vec3 d, vec3 m, double rot_amp, unsigned int seed,
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

// Vertex i (its global index; pos and forces may be a tissue's copy in shared memory, offset so
// that they are indexed by it) of replica r, whose size is s: drift mu F (plus v0 times the
// directors' mean, mode 1, or its own director, mode 2) and noise of amplitude a, projected on the
// tangent plane, then put back on the surface. A step that is not finite or above max_step (units
// of `unit`, sqrt(<A>)) leaves the vertex where it is and flags (timestep << 32 | i) in error.
__device__ __forceinline__ void brownian_vertex(
    double* pos, const double* forces, long i, const int* vertex_cells, Surface::Size s, double a, double unit,
    double* directors, int mode, double mu, double dt, double v0, double rot_amp, double max_step,
    unsigned int seed, unsigned long long timestep, unsigned long long* error)
{
    vec3 x = load3(pos, i);
    vec3 n = Surface::normal(x, s);
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
    vec3 w = dt * drift + v3(a * z0, a * z1, a * z2);
    vec3 dr = w - dot3(w, n) * n;
    double step = norm3(dr) / unit;
    if (!(step <= max_step)) {
        atomicMin(error, (timestep << 32) | (unsigned long long)i);
        return;
    }
    vec3 y = x + dr;
    vec3 m = Surface::normal(y, s);
    vec3 z = Surface::place(y, m, s);
    store3(pos, i, z);
    if (mode == 2)   // the director into the tangent plane at the new place (Active._after_move)
        store3(directors, i, transport_and_rotate(load3(directors, i), Surface::placed_normal(z, m, s), rot_amp, seed,
                                                  timestep, (unsigned int)i));
}
