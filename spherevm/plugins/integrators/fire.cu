// FIRE: the CUDA path of fire.py (same update, per-replica control), compiled once per surface
// (geometry/surface.cuh).
#include "geometry/surface.cuh"
#include "device_common.cuh"

// Per vertex: F.v, v.v, F.F summed per replica (device_common.cuh: the same bits on every run).
extern "C" __global__ void fire_reduce(
    const double* __restrict__ forces, const double* __restrict__ vel, const int* __restrict__ vertex_replica,
    int n_vertices, double* __restrict__ power, double* __restrict__ vnorm2, double* __restrict__ fnorm2,
    const int* __restrict__ vertex_start, int n_replicas, double* __restrict__ scratch,
    unsigned int* __restrict__ count)
{
    SegmentSum sums = {vertex_start, n_replicas, scratch, count};
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double p = 0.0, vv = 0.0, ff = 0.0;
    if (v < n_vertices) {
        rep = vertex_replica[v];
        vec3 f = load3(forces, v), w = load3(vel, v);
        p = dot3(f, w);
        vv = dot3(w, w);
        ff = dot3(f, f);
    }
    const double values[3] = {p, vv, ff};
    double* outs[3] = {power, vnorm2, fnorm2};
    segment_sum_partial<3>(values, rep, sums, outs, false);   // the three sums share the block's barriers
    segment_sum_finish(sums, outs, 3, false);
}

// Per replica: the FIRE control (mixing, dt, alpha, counter) from the summed power.
extern "C" __global__ void fire_control(
    int n_replicas, const double* __restrict__ power, const double* __restrict__ vnorm2,
    const double* __restrict__ fnorm2, const bool* __restrict__ active, double* __restrict__ dt,
    double* __restrict__ alpha, long long* __restrict__ n_positive, double* __restrict__ keep,
    double* __restrict__ scale, double* __restrict__ step, int n_min, double f_inc, double f_dec,
    double alpha_start, double f_alpha, double dt_max)
{
    int r = blockIdx.x * blockDim.x + threadIdx.x;
    if (r >= n_replicas) return;
    if (!active[r]) {                      // stopped: no move, dt, alpha and counter kept
        keep[r] = 0.0;
        scale[r] = 0.0;
        step[r] = 0.0;
        return;
    }
    bool uphill = power[r] <= 0.0;
    bool grow = !uphill && n_positive[r] >= n_min;
    double mix = uphill ? 0.0 : alpha[r];
    double vn = sqrt(vnorm2[r]), fn = sqrt(fnorm2[r]);
    scale[r] = fn > 0.0 ? mix * vn / fn : 0.0;
    keep[r] = uphill ? 0.0 : 1.0 - mix;
    dt[r] = uphill ? dt[r] * f_dec : (grow ? fmin(dt[r] * f_inc, dt_max) : dt[r]);
    alpha[r] = uphill ? alpha_start : (grow ? alpha[r] * f_alpha : alpha[r]);
    n_positive[r] = uphill ? 0 : n_positive[r] + 1;
    step[r] = dt[r];
}

// Per vertex: mix, semi-implicit Euler, P_N re-projection and P_T velocity transport.
// error: earliest (timestep << 32 | vertex) whose move |h w| was not finite or above
// max_step * length_unit[r] (sqrt(<A>)); that vertex is left unmoved, check() raises. size: the
// State's radius or box.
extern "C" __global__ void fire_move(
    double* __restrict__ pos, double* __restrict__ vel, const double* __restrict__ forces,
    const int* __restrict__ vertex_replica, const double* __restrict__ size, const bool* __restrict__ active,
    const double* __restrict__ keep, const double* __restrict__ scale, const double* __restrict__ step,
    int n_vertices, const double* __restrict__ length_unit, double max_step, unsigned long long step0,
    const unsigned long long* __restrict__ step_add, unsigned long long* __restrict__ error)
{
    long i = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n_vertices) return;
    unsigned long long timestep = step0 + *step_add;   // Simulation.kernel_timestep (CUDA graphs)
    int r = vertex_replica[i];
    if (!active[r]) { store3(vel, i, v3(0.0, 0.0, 0.0)); return; }
    vec3 f = load3(forces, i);
    vec3 w = keep[r] * load3(vel, i) + scale[r] * f;
    double h = step[r];
    w = w + h * f;
    double moved = norm3(h * w) / length_unit[r];
    if (!(moved <= max_step)) {
        atomicMin(error, (timestep << 32) | (unsigned long long)i);
        return;
    }
    vec3 x = load3(pos, i) + h * w;
    vec3 n = Surface::normal(x);
    x = Surface::place(x, n, Surface::size(size, r));
    w = w - dot3(w, n) * n;
    store3(pos, i, x);
    store3(vel, i, w);
}

// Integrator contract reset_vertices: zero the velocities of the listed vertices (-1: none).
extern "C" __global__ void fire_reset_vertices(double* __restrict__ vel, const int* __restrict__ vertices, int n)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    int v = vertices[i];
    if (v >= 0) store3(vel, v, v3(0.0, 0.0, 0.0));
}
