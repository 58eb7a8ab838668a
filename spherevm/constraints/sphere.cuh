// The sphere's device code (Sphere.device_surface): SphereSurface, the functions geometry/surface.cuh
// lists, on the sphere's geodesic metric (geometry/sphere.cuh's primitives).
#pragma once

#include "geometry/sphere.cuh"
#include "geometry/surface_parts.cuh"

// ------------------------------------------------------------------------------------ the sphere
struct SphereSurface {
    typedef double Size;
    static constexpr bool vertex_size = false;
    static constexpr bool directions = true;
    static constexpr bool periodic = false;   // no images (geometry/cell_measures.cu's open_cells)
    static constexpr int coef_width = 2;      // the vertex model's coefficients per cell (a_c, p_c)

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

    __device__ static vec3 normal(vec3 x, Size) { return normalize3(x); }
    __device__ static vec3 place(vec3, vec3 n, Size R) { return R * n; }
    __device__ static vec3 placed_normal(vec3, vec3 n, Size) { return n; }   // radial: P_N keeps it

    // the normalised centroid of the cell's unit vertex directions
    __device__ static vec3 cell_normal(const double* pos, const int* row, int n, Size) {
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
