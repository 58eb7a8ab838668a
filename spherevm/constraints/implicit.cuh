// The device code of a surface F(x) = 0 (ImplicitSurface.device_surface): Implicit<Shape>, the
// functions geometry/surface.cuh lists, with the flat-facet metric of constraints/flat.py (straight
// chords, vector areas, exact gradients) and the closest-point projection of
// ImplicitSurface.project_normal, the same formulas and constants. Shape (generated from the
// constraint's CUDA code for F and grad F, constraints/implicit_device.py) gives
//   k                          the parameters per replica (size_names, in order)
//   periodic                   the first two parameters are a periodic box (Lx, Ly) in x and y
//   projects                   it gives project(x, p), a closed-form closest point
//   F(x, p), grad_F(x, p)      the level set and its gradient at x, p the replica's parameters
// The size array the kernels take (ImplicitSurface.kernel_size) has k + 2 columns: the parameters,
// the length scale, half the surface's area.
#pragma once

#include "geometry/plane.cuh"
#include "geometry/surface_parts.cuh"

// ImplicitSurface's constants (constraints/implicit.py)
#define IMPLICIT_TOLERANCE 1e-14      // tolerance: a projection's last step, in length scales
#define IMPLICIT_MAX_ITERATIONS 60    // max_iterations
#define IMPLICIT_FOOT_POINT_STEPS 6   // FOOT_POINT_STEPS
#define IMPLICIT_HESSIAN_STEP 1e-5    // HESSIAN_STEP, in length scales

// x of the 4 x 4 system m x = b (Gaussian elimination with partial pivoting; m and b are overwritten)
__device__ __forceinline__ void solve4(double m[4][4], double b[4], double x[4])
{
    for (int i = 0; i < 4; ++i) {
        int pivot = i;
        for (int r = i + 1; r < 4; ++r)
            if (fabs(m[r][i]) > fabs(m[pivot][i])) pivot = r;
        if (pivot != i) {
            for (int j = 0; j < 4; ++j) { double t = m[i][j]; m[i][j] = m[pivot][j]; m[pivot][j] = t; }
            double t = b[i]; b[i] = b[pivot]; b[pivot] = t;
        }
        for (int r = i + 1; r < 4; ++r) {
            double f = m[r][i] / m[i][i];
            for (int j = i; j < 4; ++j) m[r][j] -= f * m[i][j];
            b[r] -= f * b[i];
        }
    }
    for (int i = 3; i >= 0; --i) {
        double s = b[i];
        for (int j = i + 1; j < 4; ++j) s -= m[i][j] * x[j];
        x[i] = s / m[i][i];
    }
}

template <class Shape>
struct Implicit {
    struct Size { double p[Shape::k]; double scale, half, inv_x, inv_y; };   // inv_: 1 / the period
    static constexpr bool vertex_size = true;
    static constexpr bool directions = false;     // a Norm is taken and not used
    static constexpr bool split_corners = false;  // one thread a cell
    static constexpr bool periodic = Shape::periodic;
    static constexpr int coef_width = 4;          // per cell: w = dE/dA a / A (3), dE/dP

    __device__ static Size size(const double* table, long r) {
        Size s;
        const double* row = table + (Shape::k + 2) * r;
        for (int i = 0; i < Shape::k; ++i) s.p[i] = row[i];
        s.scale = row[Shape::k];
        s.half = row[Shape::k + 1];
        s.inv_x = Shape::periodic ? 1.0 / s.p[0] : 0.0;
        s.inv_y = Shape::periodic ? 1.0 / s.p[Shape::k > 1 ? 1 : 0] : 0.0;
        return s;
    }
    __device__ static double length_scale(Size s) { return s.scale; }
    __device__ static double area_unit(Size) { return 1.0; }
    __device__ static double length_unit(Size) { return 1.0; }
    __device__ static box2 period(Size s) { box2 b = {s.p[0], s.p[1]}; return b; }   // periodic shapes only

    // ---------------------------------------------------------------- images (periodic surfaces)
    // the difference d taken to its nearest image in x and y (ImplicitSurface.nearest_images); the
    // number of periods rint(d / L) taken as rint(d (1 / L)), the same but where d / L lies within
    // rounding of a half-integer (an edge half the box long, which no valid tissue has)
    __device__ static vec3 image(vec3 d, Size s) {
        if constexpr (Shape::periodic) {
            box2 b = period(s);
            d.x -= b.x * rint(d.x * s.inv_x);
            d.y -= b.y * rint(d.y * s.inv_y);
        }
        return d;
    }
    // the image of x nearest ref (ImplicitSurface.unwrap: ref + the nearest image of x - ref in x, y)
    __device__ static vec3 unwrap(vec3 x, vec3 ref, Size s) {
        if constexpr (Shape::periodic) {
            vec3 d = image(x - ref, s);
            return v3(ref.x + d.x, ref.y + d.y, x.z);
        }
        return x;
    }
    __device__ static vec3 wrap(vec3 x, Size s) {
        if constexpr (Shape::periodic) {
            box2 b = period(s);
            return v3(wrap_coordinate(x.x, b.x), wrap_coordinate(x.y, b.y), x.z);
        }
        return x;
    }

    // ---------------------------------------------------------------- pointwise
    __device__ static vec3 normal(vec3 x, Size s) {
        vec3 g = Shape::grad_F(x, s.p);
        double n = sqrt(dot3(g, g));
        return v3(g.x / n, g.y / n, g.z / n);
    }
    __device__ static vec3 tangent(vec3 v, vec3 n) { return v - dot3(v, n) * n; }
    // the unit normal as a facet's orientation takes it (only the sign of a . sum of these is used):
    // normal's direction with one reciprocal square root for its square root and three divisions
    __device__ static vec3 facing(vec3 x, Size s) {
        vec3 g = Shape::grad_F(x, s.p);
        return rsqrt(dot3(g, g)) * g;
    }

    // One Newton step on p - x + lambda grad F(p) = 0, F(p) = 0 (the Hessian by central differences
    // of grad F), ImplicitSurface._newton_step: returns dp, updates lambda (from x - p if start).
    __device__ static vec3 newton_step(vec3 p, vec3 x, double* lam, bool start, Size s) {
        vec3 g = Shape::grad_F(p, s.p);
        double g2 = dot3(g, g);
        if (start) *lam = -dot3(x - p, g) / g2;
        double e = IMPLICIT_HESSIAN_STEP * s.scale;
        double m[4][4], b[4], delta[4];
        for (int i = 0; i < 3; ++i) {
            vec3 u = v3(i == 0 ? e : 0.0, i == 1 ? e : 0.0, i == 2 ? e : 0.0);
            vec3 column = Shape::grad_F(p + u, s.p) - Shape::grad_F(p - u, s.p);   // d grad F / d x_i
            m[0][i] = (i == 0 ? 1.0 : 0.0) + *lam * (column.x / (2.0 * e));
            m[1][i] = (i == 1 ? 1.0 : 0.0) + *lam * (column.y / (2.0 * e));
            m[2][i] = (i == 2 ? 1.0 : 0.0) + *lam * (column.z / (2.0 * e));
        }
        m[0][3] = m[3][0] = g.x;
        m[1][3] = m[3][1] = g.y;
        m[2][3] = m[3][2] = g.z;
        m[3][3] = 0.0;
        vec3 r = p - x + *lam * g;
        b[0] = -r.x; b[1] = -r.y; b[2] = -r.z; b[3] = -Shape::F(p, s.p);
        solve4(m, b, delta);
        *lam += delta[3];
        return v3(delta[0], delta[1], delta[2]);
    }

    // P_N (ImplicitSurface.project_normal): the shape's closed form, or foot-point steps
    // p <- p + P_T(p) (x - p) - F(p) grad F / |grad F|^2, then Newton steps, until a step is at most
    // IMPLICIT_TOLERANCE length scales; wrapped into the box. NaN where it does not converge (the
    // run's check of finite positions reports it).
    __device__ static vec3 project(vec3 x, Size s) {
        vec3 p = x;
        if constexpr (Shape::projects) {
            p = Shape::project(x, s.p);
        } else {
            double limit = IMPLICIT_TOLERANCE * s.scale, lam = 0.0;
            bool done = false;
            for (int it = 0; it < IMPLICIT_MAX_ITERATIONS && !done; ++it) {
                vec3 step;
                if (it < IMPLICIT_FOOT_POINT_STEPS) {
                    vec3 g = Shape::grad_F(p, s.p);
                    step = (x - p) - ((dot3(x - p, g) + Shape::F(p, s.p)) / dot3(g, g)) * g;
                } else {
                    step = newton_step(p, x, &lam, it == IMPLICIT_FOOT_POINT_STEPS, s);
                }
                p = p + step;
                done = sqrt(dot3(step, step)) <= limit;
            }
            if (!done) p = v3(nan(""), nan(""), nan(""));
        }
        return wrap(p, s);
    }
    __device__ static vec3 place(vec3 y, vec3, Size s) { return project(y, s); }
    // off the surface grad F need not point along the normal line of the closest point (it does on
    // the torus, not on the ellipsoid): the normal is taken again where the point landed
    __device__ static vec3 placed_normal(vec3 x, vec3, Size s) { return normal(x, s); }

    // ---------------------------------------------------------------- the flat-facet metric
    // A cell's vector area a (the fan r x e / 2 about its first vertex, r and e nearest images), its
    // perimeter (the chords) and its area |a| signed by a . sum of the normals at its vertices
    // (FlatFacets.cell_geometry, flat.signed_area; the normals rounded otherwise, which changes the
    // sign only where a . sum is within rounding of zero: a cell of no area or folded on edge).
    __device__ static void facet(const double* pos, const int* row, int n, Size s, double* area, double* perimeter,
                                 vec3* vector) {
        vec3 first = load3(pos, row[0]), a = v3(0.0, 0.0, 0.0), reference = v3(0.0, 0.0, 0.0);
        double length = 0.0;
        vec3 xv = first;
        for (int j = 0; j < n; ++j) {
            vec3 xn = j + 1 < n ? load3(pos, row[j + 1]) : first;
            vec3 e = image(xn - xv, s);
            a = a + 0.5 * cross3(image(xv - first, s), e);
            length += norm3(e);
            reference = reference + facing(xv, s);
            xv = xn;
        }
        double d = dot3(a, reference);
        *area = (d > 0.0 ? 1.0 : d < 0.0 ? -1.0 : 0.0) * norm3(a);
        *perimeter = length;
        *vector = a;
    }
    template <class Norm = RsqrtNorm>
    __device__ static void cell_measures(const double* pos, const int* row, int n, Size s, double* area,
                                         double* perimeter, const Norm& = Norm()) {
        vec3 a;
        facet(pos, row, n, s, area, perimeter, &a);
    }

    // Minus the flat-facet shape gradient at v (FlatFacets.shape_gradient), coef per cell c as
    // (w_c, q_c) = (dE/dA a_c / A_c, dE/dP): cell k at v adds (e_k - e_{k+1}) x w / 2, the edge
    // v -> n_k adds -(q_k + q_{k-1}) e_k / |e_k|; projected on the tangent plane at v.
    template <class Extra = NoExtra, class Norm = RsqrtNorm>   // no force is fused into these kernels
    __device__ static vec3 vertex_force(const double* pos, const int* vn, const int* vc, long v, Size s,
                                        const double* coef, const Extra& = Extra(), const Norm& = Norm()) {
        vec3 x = load3(pos, v);
        vec3 e[3];
        for (int k = 0; k < 3; ++k) e[k] = image(load3(pos, vn[3 * v + k]) - x, s);
        vec3 g = v3(0.0, 0.0, 0.0);
        for (int k = 0; k < 3; ++k) {
            int c = vc[3 * v + k], before = vc[3 * v + (k + 2) % 3];
            double len = norm3(e[k]);
            vec3 w = v3(coef[4 * c], coef[4 * c + 1], coef[4 * c + 2]);
            g = g + 0.5 * cross3(e[k] - e[(k + 1) % 3], w)
                  + (-(coef[4 * c + 3] + coef[4 * before + 3]) / (len > 0.0 ? len : 1.0)) * e[k];
        }
        vec3 n = normal(x, s);
        return -tangent(g, n);
    }

    // the centre of the cell's vertices (unwrapped about its first) put on the surface, its normal
    // (ImplicitSurface.cell_normals)
    __device__ static vec3 cell_normal(const double* pos, const int* row, int n, Size s) {
        vec3 first = load3(pos, row[0]), sum = v3(0.0, 0.0, 0.0);
        for (int k = 0; k < n; ++k) sum = sum + unwrap(load3(pos, row[k]), first, s);
        return normal(project(v3(sum.x / n, sum.y / n, sum.z / n), s), s);
    }

    // ---------------------------------------------------------------- T1
    __device__ static double chord2(vec3 pu, vec3 pv, Size s) { vec3 d = unwrap(pv, pu, s) - pu; return dot3(d, d); }
    __device__ static double edge_length(vec3 pu, vec3 pv, Size s) { return sqrt(chord2(pu, pv, s)); }

    // ImplicitSurface.triangle_area: the flat area of (a, b, c), b and c as seen from a, signed by
    // the normal at a; half the surface's area; b - a as seen from a.
    __device__ static double triangle_area(vec3 a, vec3 b, vec3 c, Size s) {
        vec3 v = 0.5 * cross3(unwrap(b, a, s) - a, unwrap(c, a, s) - a);
        double d = dot3(v, normal(a, s));
        return (d > 0.0 ? 1.0 : d < 0.0 ? -1.0 : 0.0) * norm3(v);
    }
    __device__ static double half_area(Size s) { return s.half; }
    __device__ static vec3 delta(vec3 a, vec3 b, Size s) { return unwrap(b, a, s) - a; }
    // ImplicitSurface.orientation_points: p as seen from ref in the frame of the plane tangent at
    // ref (e1 from the axis least aligned with the normal), (u, v, 1)
    __device__ static vec3 crossing_point(vec3 p, vec3 ref, Size s) {
        vec3 n = normal(ref, s);
        double ax = fabs(n.x), ay = fabs(n.y), az = fabs(n.z);
        vec3 seed = ax <= ay && ax <= az ? v3(1.0, 0.0, 0.0) : ay <= az ? v3(0.0, 1.0, 0.0) : v3(0.0, 0.0, 1.0);
        vec3 e1 = seed - dot3(seed, n) * n;
        double l = sqrt(dot3(e1, e1));
        e1 = v3(e1.x / l, e1.y / l, e1.z / l);
        vec3 e2 = cross3(n, e1), r = unwrap(p, ref, s) - ref;
        return v3(dot3(r, e1), dot3(r, e2), 1.0);
    }

    // topology.t1_new_positions: the edge turned by 90 degrees about the normal at its projected
    // midpoint (a zero-length edge towards the side of the cells at a and d; `turn`: the other way),
    // each end `full` / 2 along the tangent from the midpoint, projected back. x_pos: X = v, y_pos: Y = u.
    __device__ static void t1_positions(const double* pos, int u, int v, int a, int b, int c, int d, Size s,
                                        double full, vec3* x_pos, vec3* y_pos, bool turn = false) {
        vec3 pu = load3(pos, u), pv = unwrap(load3(pos, v), pu, s);
        vec3 mid = project(0.5 * (pu + pv), s);
        vec3 nrm = normal(mid, s);
        vec3 along = tangent(pv - pu, nrm);
        double len = norm3(along);
        vec3 perp;
        if (len <= 1e-12 * s.scale) {
            vec3 pa = unwrap(load3(pos, a), pu, s), pb = unwrap(load3(pos, b), pu, s);
            vec3 pc = unwrap(load3(pos, c), pu, s), pd = unwrap(load3(pos, d), pu, s);
            perp = tangent(0.5 * (pa + pd) - 0.5 * (pb + pc), nrm);
        } else {
            perp = cross3(nrm, v3(along.x / len, along.y / len, along.z / len));
        }
        if (turn) perp = -perp;
        double l = norm3(perp);
        perp = v3(perp.x / l, perp.y / l, perp.z / l);
        double half = 0.5 * full;
        *x_pos = project(mid + half * perp, s);
        *y_pos = project(mid + half * (-perp), s);
    }
};
