// The periodic plane's device code (PeriodicPlane.device_surface): PlaneSurface, the functions
// geometry/surface.cuh lists, on minimum images in the replica's box (geometry/plane.cuh's primitives).
#pragma once

#include "geometry/plane.cuh"
#include "geometry/surface_parts.cuh"

// ------------------------------------------------------------------------------------ the plane
struct PlaneSurface {
    typedef box2 Size;
    static constexpr bool vertex_size = true;
    static constexpr bool periodic = true;    // minimum images in the box period(b) = b
    __device__ static box2 period(Size b) { return b; }
    static constexpr int coef_width = 2;      // the vertex model's coefficients per cell (a_c, p_c)

    __device__ static Size size(const double* box, long r) { return load_box(box, r); }
    __device__ static double length_scale(Size b) { return sqrt(b.x * b.y); }
    __device__ static double area_unit(Size) { return 1.0; }
    __device__ static double length_unit(Size) { return 1.0; }

    // the shoelace sum runs on prefix sums of the edges: one thread a cell
    static constexpr bool split_corners = false;
    static constexpr bool directions = false;   // a Norm is taken and not used
    template <class Norm = RsqrtNorm>
    __device__ static void cell_measures(const double* pos, const int* row, int n, Size b, double* area,
                                         double* perimeter, const Norm& = Norm()) {
        plane_cell_measures(pos, row, n, b, area, perimeter);
    }

    template <class Extra = NoExtra, class Norm = RsqrtNorm>   // no force is fused into the plane's kernels
    __device__ static vec3 vertex_force(const double* pos, const int* vn, const int* vc, long v, Size b,
                                        const double* coef, const Extra& = Extra(), const Norm& = Norm()) {
        return -plane_vertex_gradient(pos, vn, vc, v, b, coef);
    }

    __device__ static vec3 normal(vec3, Size) { return v3(0.0, 0.0, 1.0); }
    __device__ static vec3 place(vec3 y, vec3, Size b) { return wrap_into_box(y, b); }
    __device__ static vec3 placed_normal(vec3, vec3 n, Size) { return n; }   // one normal everywhere
    __device__ static vec3 cell_normal(const double*, const int*, int, Size) { return v3(0.0, 0.0, 1.0); }

    // T1 takes the edge as PeriodicPlane.displacement(u, v): the minimum image of x_v - x_u
    __device__ static double chord2(vec3 pu, vec3 pv, Size b) { return plane_length2(plane_edge(pu, pv, b)); }
    __device__ static double edge_length(vec3 pu, vec3 pv, Size b) { return plane_length(plane_edge(pu, pv, b)); }

    // PeriodicPlane.triangle_area (b and c as seen from a), half the box, the minimum image of b - a.
    __device__ static double triangle_area(vec3 a, vec3 b, vec3 c, Size box) {
        vec3 u = minimum_image(b - a, box), v = minimum_image(c - a, box);
        return 0.5 * (u.x * v.y - u.y * v.x);
    }
    __device__ static double half_area(Size box) { return 0.5 * (box.x * box.y); }
    __device__ static vec3 delta(vec3 a, vec3 b, Size box) { return minimum_image(b - a, box); }
    // (x, y, 1) of p's image nearest ref, as PeriodicPlane.unwrap forms it (no fused multiply-adds)
    __device__ static vec3 crossing_point(vec3 p, vec3 ref, Size box) {
        double dx = __dsub_rn(p.x, ref.x), dy = __dsub_rn(p.y, ref.y);
        dx = __dsub_rn(dx, __dmul_rn(box.x, rint(__ddiv_rn(dx, box.x))));
        dy = __dsub_rn(dy, __dmul_rn(box.y, rint(__ddiv_rn(dy, box.y))));
        return v3(__dadd_rn(ref.x, dx), __dadd_rn(ref.y, dy), 1.0);
    }

    // topology.t1_flip on the plane: v, a, b, c, d unwrapped about u; the midpoint wrapped into the
    // box; the edge turned by +90 degrees about z (-90 with `turn`); each end `full` / 2 from the
    // midpoint, wrapped.
    __device__ static void t1_positions(const double* pos, int u, int v, int a, int b, int c, int d, Size box,
                                        double full, vec3* x_pos, vec3* y_pos, bool turn = false) {
        vec3 pu = load3(pos, u);
        pu.z = 0.0;
        vec3 pv = plane_unwrap(load3(pos, v), pu, box);
        vec3 mid = wrap_into_box(0.5 * (pu + pv), box);
        vec3 along = pv - pu;
        double len = sqrt(along.x * along.x + along.y * along.y);
        vec3 perp;
        if (len <= 1e-12 * length_scale(box)) {
            vec3 pa = plane_unwrap(load3(pos, a), pu, box), pb = plane_unwrap(load3(pos, b), pu, box);
            vec3 pc = plane_unwrap(load3(pos, c), pu, box), pd = plane_unwrap(load3(pos, d), pu, box);
            perp = 0.5 * (pa + pd) - 0.5 * (pb + pc);
        } else {
            perp = v3(-(along.y / len), along.x / len, 0.0);
        }
        if (turn) perp = -perp;
        double n = sqrt(perp.x * perp.x + perp.y * perp.y);
        perp = v3(perp.x / n, perp.y / n, 0.0);
        double half = 0.5 * full;
        *x_pos = wrap_into_box(mid + half * perp, box);
        *y_pos = wrap_into_box(mid + half * (-perp), box);
    }
};
