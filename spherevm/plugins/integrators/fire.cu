// FIRE: the CUDA path of fire.py (same update, per-replica control), compiled once per surface
// (geometry/surface.cuh): two kernels an iteration, the sums with the control, and the move. The
// control and the move are fire.cuh's (shared with the fused small-tissue minimisation).
#include "plugins/integrators/fire.cuh"
#include "device_common.cuh"

// Per vertex: F.v, v.v, F.F summed per replica (device_common.cuh: the same bits on every run);
// then per replica, once its sums are final, the FIRE control (mixing, dt, alpha, counter: fire.cuh)
// into keep, scale and step, which fire_move reads. A stopped replica (active false) gets no move,
// and keeps its dt, alpha and counter. At most 48 registers (5 blocks of 256 threads an SM; 56
// unbounded, 4 blocks): the kernel's time is its blocks' chains of latencies, so more blocks in
// flight help (on an H200, 1,024 x 32 cells 10 against 17 us, 1e6 cells 72 against 82).
extern "C" __global__ void __launch_bounds__(256, 5) fire_reduce(
    const double* __restrict__ forces, const double* __restrict__ vel, const int* __restrict__ vertex_replica,
    int n_vertices, double* __restrict__ power, double* __restrict__ vnorm2, double* __restrict__ fnorm2,
    const int* __restrict__ vertex_start, int n_replicas, double* __restrict__ scratch,
    unsigned int* __restrict__ count, const bool* __restrict__ active, double* __restrict__ dt,
    double* __restrict__ alpha, long long* __restrict__ n_positive, double* __restrict__ keep,
    double* __restrict__ scale, double* __restrict__ step, int n_min, double f_inc, double f_dec,
    double alpha_start, double f_alpha, double dt_max)
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
    const FireParams params = {n_min, f_inc, f_dec, alpha_start, f_alpha, dt_max};
    auto control = [&](int r) {
        if (!active[r]) {
            keep[r] = 0.0;
            scale[r] = 0.0;
            step[r] = 0.0;
            return;
        }
        fire_control_replica(power[r], vnorm2[r], fnorm2[r], dt + r, alpha + r, n_positive + r, params, keep + r,
                             scale + r, step + r);
    };
    segment_sums<3>(values, rep, sums, outs, false, control);   // the three sums share the block's barriers
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
    fire_move_vertex(pos, vel, forces, i, Surface::size(size, r), keep[r], scale[r], step[r], length_unit[r], max_step,
                     timestep, error);
}

// Integrator contract reset_vertices: zero the velocities of the listed vertices (-1: none).
extern "C" __global__ void fire_reset_vertices(double* __restrict__ vel, const int* __restrict__ vertices, int n)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    int v = vertices[i];
    if (v >= 0) store3(vel, v, v3(0.0, 0.0, 0.0));
}
