// FIRE's stage of the fused small-tissue minimisation (spherevm/tissue_steps.cu, FIRE.fused_stage):
// the per-vertex terms of its per-replica sums (F.v, |v|^2, |F|^2), its control (fire_control_replica,
// on one thread) and its move (fire_move_vertex), the functions of fire.cu's kernels, so the fused
// minimisation is theirs bit for bit. FireArgs is declared from its Python definition
// (FIRE.FUSED_ARGS): the velocities, dt, alpha and counter per replica, the constants, sqrt(<A>) per
// replica, max_step and the error word.
#pragma once
#include "plugins/integrators/fire.cuh"

struct FireStage {
    static constexpr bool minimizer = true;
    static constexpr int n_sums = 3;          // F.v, |v|^2, |F|^2
    static constexpr int vertex_doubles = 3;  // the velocity, kept in shared memory through the launch
    FireArgs a;

    // A replica's dt, alpha and counter, which one thread keeps through the launch.
    struct Control {
        double dt, alpha;
        long long positive;
    };

    __device__ __forceinline__ double* vertex_state() const { return a.vel; }
    __device__ __forceinline__ Control load(int r) const { return Control{a.dt[r], a.alpha[r], a.n_positive[r]}; }
    __device__ __forceinline__ void store(int r, const Control& c) const
    {
        a.dt[r] = c.dt;
        a.alpha[r] = c.alpha;
        a.n_positive[r] = c.positive;
    }

    // Vertex v's terms of the sums, from its force f and velocity w.
    __device__ __forceinline__ void terms(vec3 f, vec3 w, double* t) const
    {
        t[0] = dot3(f, w);
        t[1] = dot3(w, w);
        t[2] = dot3(f, f);
    }

    // The replica's control from its sums: the mixing and step into out[0..2] (keep, scale, step).
    __device__ __forceinline__ void control(const double* sums, Control* c, double* out) const
    {
        const FireParams p = {a.n_min, a.f_inc, a.f_dec, a.alpha_start, a.f_alpha, a.dt_max};
        fire_control_replica(sums[0], sums[1], sums[2], &c->dt, &c->alpha, &c->positive, p, out, out + 1, out + 2);
    }

    // Vertex v of replica r moves (pos, V: positions and velocities; F: forces; ctl: the control).
    __device__ __forceinline__ void vertex(double* pos, double* V, const double* F, long v, Surface::Size s, int r,
                                           const double* ctl, unsigned long long timestep) const
    {
        fire_move_vertex(pos, V, F, v, s, ctl[0], ctl[1], ctl[2], a.length_unit[r], a.max_step, timestep, a.error);
    }

    // A flipped vertex forgets its velocity (T1's reset_velocities, as fire_reset_vertices).
    __device__ __forceinline__ void reset_vertex(double* V, long v) const { store3(V, v, v3(0.0, 0.0, 0.0)); }
};
