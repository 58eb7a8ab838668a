// The surface a kernel is compiled for: one kernel source serves every surface. Each surface is a
// struct of static device functions with the same names; a kernel calls them through `Surface`,
// which is PlaneSurface when the module is compiled with -DSVM_SURFACE_PLANE and SphereSurface
// otherwise (spherevm.constraints.kernels.surface_kernels picks the flag from the State's constraint).
//
//   Size                      the per-replica size (a radius, or a box (Lx, Ly))
//   size(s, r)                replica r's size from the State's size array (radius or box)
//   vertex_size               whether the vertex-force kernel needs each vertex's size
//   directions                whether the vertex model's functions use the vertices' unit directions
//                             x / |x| (the sphere), through a Norm: 1 / |x| of vertex i, computed
//                             (RsqrtNorm, the default) or kept from before (KeptNorm)
//   cell_measures(...)        a cell's area and perimeter
//   area_unit, length_unit    what the vertex-force coefficients are scaled by
//   vertex_force(...)         minus the surface gradient of sum_c a_c A_c + p_c P_c at a vertex (on the
//                             sphere a force fused into the vertex model adds its gradient through
//                             an `extra`, see plugins/forces/vertex_model.cuh)
//   normal(x)                 the unit normal at x
//   place(y, n, s)            P_N: the surface point for y, whose normal n = normal(y) the caller has
//   cell_normal(...)          the normal at a cell's centre (active cell directors)
//   chord2, edge_length       the T1 short-edge test and the edge's length
//   t1_positions(...)         the two vertices of a flipped edge
//   triangle_area(a, b, c, s) the sign-carrying area of a triangle, half_area(s) half the surface's
//                             in the same unit, delta(a, b, s) the vector a -> b (T1's fold rule,
//                             plugins/updaters/t1_fold.cuh)
//   crossing_point(p, ref, s) p as a 3-vector whose triple products give orientations, the image
//                             nearest ref on the plane (simplicity.points; T1's untangling)
#pragma once

#include "geometry/plane.cuh"
#include "geometry/sphere.cuh"

// What a force fused into the vertex model's kernels adds (nothing): see plugins/forces/vertex_model.cuh.
struct NoExtra {
    static constexpr bool sums_energy = false;   // true: the extra's own kernel sums the cells' energies
    __device__ __forceinline__ void cell(const double*, const int*, int, long) const {}
    __device__ __forceinline__ void add_gradient(vec3&, const double*, const int*, const int*, long, vec3) const {}
};

// 1 / |x| of vertex i (rsqrt), for a unit direction x / |x|: computed from the position where it is
// used (RsqrtNorm: the general kernels), or kept from before in an array (KeptNorm: the fused
// small-tissue steps compute each vertex's once a step, not in each of its three cells and four
// vertex forces). Both give the same bits: the array holds what RsqrtNorm returns.
// |x|^2 is written out in the form the compiler gave normalize3's dot3 in these functions (x x + y y
// fused as fma(x, x, y y)), which it would otherwise choose by where the function is inlined.
struct RsqrtNorm {
    __device__ __forceinline__ double operator()(const double* pos, long i) const {
        vec3 p = load3(pos, i);
        return rsqrt(__fma_rn(p.z, p.z, __fma_rn(p.x, p.x, __dmul_rn(p.y, p.y))));
    }
};
struct KeptNorm {
    const double* inv;   // indexed as the positions are
    __device__ __forceinline__ double operator()(const double*, long i) const { return inv[i]; }
};

// ------------------------------------------------------------------------------------ the sphere
struct SphereSurface {
    typedef double Size;
    static constexpr bool vertex_size = false;
    static constexpr bool directions = true;

    // vertex i's unit direction (the products rounded as written, as normalize3's are compiled here)
    template <class Norm>
    __device__ static vec3 direction(const double* pos, long i, const Norm& norm) {
        return mul3_rn(norm(pos, i), load3(pos, i));
    }

    __device__ static Size size(const double* radius, long r) { return radius[r]; }
    __device__ static double length_scale(Size R) { return R; }
    __device__ static double area_unit(Size R) { return R * R; }
    __device__ static double length_unit(Size R) { return R; }

    // Area: a fan about the cell's first vertex a, each triangle (a, b, d) as den + i num with
    // num = (a - b).(b x d), den = 1 + b.d + a.(b + d), the area 2 arg of their product: one atan2
    // per cell, valid below a hemisphere. Perimeter: the sum of the arcs. Each corner's terms are
    // independent (corner, cell_corner); only their sum and product run in the cell's order
    // (CellSum), so the fused small-tissue steps spread a cell's corners over several threads
    // (split_corners) and get these bits.
    static constexpr bool split_corners = true;
    struct Corner { double half, num, den; };    // the edge b -> d's half arc, the fan triangle's factor
    struct CellSum { double P, re, im; };        // the arcs' sum, the product of the factors so far

    __device__ static Corner corner(vec3 a, vec3 b, vec3 d) {
        edge_terms t = make_edge(b, d);
        Corner k = {half_angle(t), dot3(a - b, t.x), 0.5 * t.q + dot3(a, b + d)};
        return k;
    }
    // corner i of the cell (row, n sides) whose first vertex's direction is a
    template <class Norm>
    __device__ static Corner cell_corner(const double* pos, const int* row, int n, int i, vec3 a, const Norm& norm) {
        vec3 b = i == 0 ? a : direction(pos, row[i], norm);
        vec3 d = i + 1 < n ? direction(pos, row[i + 1], norm) : a;
        return corner(a, b, d);
    }
    // the next corner into the sums, rounded as written (the forms the compiler chose for
    // cell_measures' loop: re den - im num as one fused multiply-add), so that the threads of the
    // fused steps and cell_measures give the same bits
    __device__ static void add_corner(CellSum* sum, Corner k) {
        double re = __fma_rn(sum->re, k.den, -__dmul_rn(sum->im, k.num));
        sum->im = __fma_rn(sum->im, k.den, __dmul_rn(sum->re, k.num));
        sum->re = re;
        sum->P = __dadd_rn(sum->P, k.half);
    }
    __device__ static void finish_measures(CellSum sum, Size R, double* area, double* perimeter) {
        *area = 2.0 * atan2(sum.im, sum.re) * (R * R);
        *perimeter = sum.P * (2.0 * R);
    }

    template <class Norm = RsqrtNorm>
    __device__ static void cell_measures(const double* pos, const int* row, int n, Size R, double* area,
                                         double* perimeter, const Norm& norm = Norm()) {
        vec3 a = direction(pos, row[0], norm);
        vec3 b = a;
        CellSum sum = {0.0, 1.0, 0.0};
        for (int i = 0; i < n; ++i) {
            vec3 d = i + 1 < n ? direction(pos, row[i + 1], norm) : a;
            add_corner(&sum, corner(a, b, d));
            b = d;
        }
        finish_measures(sum, R, area, perimeter);
    }

    // Each of v's edges v -> n_j lies in cell j (slot j) and, as n_j -> v, in cell j-1 (slot j+2
    // mod 3): sum_j (coefA[j-1] - coefA[j]) w(v, n_j) + (coefP[j] + coefP[j-1]) d theta_j / dv on
    // the unit sphere (coefficients carry R^2 and R), projected on the tangent plane, as in
    // Sphere.shape_gradient.
    template <class Extra = NoExtra, class Norm = RsqrtNorm>
    __device__ static vec3 vertex_force(const double* pos, const int* vn, const int* vc, long v, Size,
                                        const double* coef, const Extra& extra = Extra(), const Norm& norm = Norm()) {
        vec3 r = load3(pos, v);
        double inv_rn = norm(pos, v);
        vec3 u = inv_rn * r;
        vec3 g = v3(0.0, 0.0, 0.0);
        for (int j = 0; j < 3; ++j) {
            int c_next = vc[3 * v + j], c_prev = vc[3 * v + (j + 2) % 3], w = vn[3 * v + j];
            edge_terms t = make_edge_to(u, norm(pos, w), load3(pos, w));
            g = g + (coef[2 * c_prev] - coef[2 * c_next]) * edge_area_term(t)
                  + (coef[2 * c_next + 1] + coef[2 * c_prev + 1]) * edge_length_term(t);
        }
        extra.add_gradient(g, pos, vn, vc, v, r);   // a fused force's terms, in the same units
        g = g - dot3(g, u) * u;
        return -(inv_rn * g);
    }

    __device__ static vec3 normal(vec3 x) { return normalize3(x); }
    __device__ static vec3 place(vec3, vec3 n, Size R) { return R * n; }

    // the normalised centroid of the cell's unit vertex directions
    __device__ static vec3 cell_normal(const double* pos, const int* row, int n) {
        vec3 sum = v3(0.0, 0.0, 0.0);
        for (int k = 0; k < n; ++k) sum = sum + normalize3(load3(pos, row[k]));
        return normalize3(sum);
    }

    __device__ static double chord2(vec3 pu, vec3 pv, Size) { vec3 c = pu - pv; return dot3(c, c); }
    __device__ static double edge_length(vec3 pu, vec3 pv, Size R) {
        return R * geodesic_length(normalize3(pu), normalize3(pv));
    }

    // The solid angle of the unit vectors (Sphere.triangle_area without its R^2), a hemisphere's, b - a.
    __device__ static double triangle_area(vec3 a, vec3 b, vec3 c, Size) {
        return solid_angle(normalize3(a), normalize3(b), normalize3(c));
    }
    __device__ static double half_area(Size) { return 6.283185307179586; }   // 2 pi, as NumPy's float64
    __device__ static vec3 delta(vec3 a, vec3 b, Size) { return b - a; }
    // the unit vector p / |p|, |p|^2 summed as NumPy sums a row, without fused multiply-adds
    __device__ static vec3 crossing_point(vec3 p, vec3, Size) {
        double n = sqrt(__dadd_rn(__dadd_rn(__dmul_rn(p.x, p.x), __dmul_rn(p.y, p.y)), __dmul_rn(p.z, p.z)));
        return v3(__ddiv_rn(p.x, n), __ddiv_rn(p.y, n), __ddiv_rn(p.z, n));
    }

    // The edge u-v rotated by 90 degrees about the normal at its midpoint, its ends at geodesic
    // distance `full` apart (exact geodesic offsets); a zero-length edge turns towards the side of
    // the cells at a and d; `turn`: the other way round (topology.t1_new_positions). x_pos goes to
    // X = v (the C1 side), y_pos to Y = u.
    __device__ static void t1_positions(const double* pos, int u, int v, int a, int b, int c, int d, Size R,
                                        double full, vec3* x_pos, vec3* y_pos, bool turn = false) {
        vec3 pu = load3(pos, u), pv = load3(pos, v);
        vec3 mid = R * normalize3(0.5 * (pu + pv));
        vec3 nrm = normalize3(mid);
        vec3 w = pv - pu;
        vec3 along = w - dot3(w, nrm) * nrm;
        double len = norm3(along);
        vec3 perp;
        if (len <= 1e-12 * R) {
            vec3 s = 0.5 * (load3(pos, a) + load3(pos, d)) - 0.5 * (load3(pos, b) + load3(pos, c));
            perp = s - dot3(s, nrm) * nrm;
        } else {
            perp = cross3(nrm, v3(along.x / len, along.y / len, along.z / len));
        }
        if (turn) perp = -perp;
        perp = normalize3(perp);
        double phi = 0.5 * full / R;
        vec3 m = normalize3(mid);
        *x_pos = R * (cos(phi) * m + sin(phi) * perp);
        *y_pos = R * (cos(phi) * m + sin(phi) * (-perp));
    }
};

// ------------------------------------------------------------------------------------ the plane
struct PlaneSurface {
    typedef box2 Size;
    static constexpr bool vertex_size = true;

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

    __device__ static vec3 normal(vec3) { return v3(0.0, 0.0, 1.0); }
    __device__ static vec3 place(vec3 y, vec3, Size b) { return wrap_into_box(y, b); }
    __device__ static vec3 cell_normal(const double*, const int*, int) { return v3(0.0, 0.0, 1.0); }

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

#ifdef SVM_SURFACE_PLANE
typedef PlaneSurface Surface;
#else
typedef SphereSurface Surface;
#endif
