// FIRE's per-replica control and per-vertex move: the bodies of fire.cu's kernels and of the fused
// small-tissue minimisation (spherevm/tissue_steps.cu), so both give the same bits. Compiled once
// per surface (geometry/surface.cuh).
#pragma once
#include "geometry/surface.cuh"

// FIRE's constants (fire.py): n_min, f_inc, f_dec, alpha_start, f_alpha, dt_max.
struct FireParams {
    int n_min;
    double f_inc, f_dec, alpha_start, f_alpha, dt_max;
};

// One running replica (FIRE.move): from the summed power F.v and the squared norms |v|^2 and |F|^2,
// the mixing (keep, scale), the new dt, alpha and counter, and the step it moves by (the new dt).
__device__ __forceinline__ void fire_control_replica(double power, double vnorm2, double fnorm2, double* dt,
                                                     double* alpha, long long* n_positive, const FireParams& p,
                                                     double* keep, double* scale, double* step)
{
    bool uphill = power <= 0.0;
    bool grow = !uphill && *n_positive >= p.n_min;
    double mix = uphill ? 0.0 : *alpha;
    double vn = sqrt(vnorm2), fn = sqrt(fnorm2);
    *scale = fn > 0.0 ? mix * vn / fn : 0.0;
    *keep = uphill ? 0.0 : 1.0 - mix;
    *dt = uphill ? *dt * p.f_dec : (grow ? fmin(*dt * p.f_inc, p.dt_max) : *dt);
    *alpha = uphill ? p.alpha_start : (grow ? *alpha * p.f_alpha : *alpha);
    *n_positive = uphill ? 0 : *n_positive + 1;
    *step = *dt;
}

// Vertex i (its global index; pos, vel and forces may be a tissue's copies in shared memory, offset
// so that they are indexed by it) of a running replica whose size is s: mix, semi-implicit Euler,
// P_N re-projection and P_T velocity transport. A move |h w| that is not finite or above max_step
// units (sqrt(<A>)) leaves the vertex and its velocity as they were and flags (timestep << 32 | i).
// The arithmetic is written out (vec3.cuh's rounded helpers) in the forms fire.cu's kernel compiled
// to when it held this code itself: w = fma(keep, v, scale f), w = fma(h, f, w), x = x + (h w),
// w = fma(-(w.n), n, w), so it has the same bits wherever it is inlined (fire.cu's kernel, the fused
// minimisation). Left to the compiler, the mix becomes (keep v) + fma(scale, f) in one and
// fma(keep, v, scale f) in the other.
__device__ __forceinline__ void fire_move_vertex(double* pos, double* vel, const double* forces, long i,
                                                 Surface::Size s, double keep, double scale, double h, double unit,
                                                 double max_step, unsigned long long timestep,
                                                 unsigned long long* error)
{
    vec3 f = load3(forces, i);
    vec3 w = fma3_rn(h, f, fma3_rn(keep, load3(vel, i), mul3_rn(scale, f)));
    vec3 hw = mul3_rn(h, w);
    double moved = norm3(hw) / unit;
    if (!(moved <= max_step)) {
        atomicMin(error, (timestep << 32) | (unsigned long long)i);
        return;
    }
    vec3 x = add3_rn(load3(pos, i), hw);
    vec3 n = Surface::normal(x, s);
    x = Surface::place(x, n, s);
    n = Surface::placed_normal(x, n, s);       // P_T at the new place, as FIRE._move_cpu
    w = fma3_rn(-dot3(w, n), n, w);
    store3(pos, i, x);
    store3(vel, i, w);
}
