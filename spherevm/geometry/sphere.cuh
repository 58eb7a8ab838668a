// Metric primitives of the sphere, the CUDA twin of spherevm/geometry/sphere.py (same formulas).
// Unit vectors in, angles and solid angles out; multiply by R and R^2 for a sphere of radius R.
#pragma once

#include "geometry/vec3.cuh"

// geodesic angle, half-angle form: 2 atan2(|a - b|, |a + b|)
__device__ __forceinline__ double geodesic_length(vec3 a, vec3 b) {
    return 2.0 * atan2(norm3(a - b), norm3(a + b));
}

// gradient of geodesic_length(a, b) with respect to a: -t/|t|, t = (b - a) - ((b - a).a) a; 0 if t = 0
__device__ __forceinline__ vec3 geodesic_length_gradient(vec3 a, vec3 b) {
    vec3 d = b - a;
    vec3 t = d - dot3(d, a) * a;
    double n2 = dot3(t, t);
    double s = n2 > 0.0 ? -rsqrt(n2) : 0.0;
    return s * t;
}

// signed solid angle of the geodesic triangle (a, b, c): 2 atan2(a.(b x c), 1 + a.b + b.c + c.a)
__device__ __forceinline__ double solid_angle(vec3 a, vec3 b, vec3 c) {
    double num = dot3(a, cross3(b, c));
    double den = 1.0 + dot3(a, b) + dot3(b, c) + dot3(c, a);
    return 2.0 * atan2(num, den);
}

// gradient of solid_angle(a, b, c) with respect to the middle vertex b (not projected):
// 2 (D (c x a) - N (a + c)) / (N^2 + D^2)
__device__ __forceinline__ vec3 solid_angle_gradient(vec3 a, vec3 b, vec3 c) {
    double num = dot3(a, cross3(b, c));
    double den = 1.0 + dot3(a, b) + dot3(b, c) + dot3(c, a);
    vec3 g = den * cross3(c, a) - num * (a + c);
    double s = 2.0 / (num * num + den * den);
    return s * g;
}

// The edge b -> d of a cell (unit vectors), in the terms Sphere.cell_geometry uses:
// m = b - d, q = |b + d|^2 = 4 - |m|^2, x = b x d (taken as m x b, accurate for short edges).
struct edge_terms { vec3 m, x; double m2, q; };

__device__ __forceinline__ edge_terms make_edge(vec3 b, vec3 d) {
    edge_terms e;
    e.m = b - d;
    e.m2 = dot3(e.m, e.m);
    e.q = fmax(4.0 - e.m2, 0.0);
    e.x = cross3(e.m, b);
    return e;
}

// The edge u -> w (u a unit direction, w at p with inverse norm inv = rsqrt(|p|^2)) as make_edge(u,
// normalize3(p)) is compiled: w's direction is used only in m, so the compiler fuses its products
// into the difference, m = u - inv p rounded once; written out so that an inverse norm kept from
// before (the fused small-tissue steps) gives the same bits.
__device__ __forceinline__ edge_terms make_edge_to(vec3 u, double inv, vec3 p) {
    edge_terms e;
    e.m = fma3_rn(-inv, p, u);
    e.m2 = dot3(e.m, e.m);
    e.q = fmax(4.0 - e.m2, 0.0);
    e.x = cross3(e.m, u);
    return e;
}

// half the edge's angle: atan2(|b - d|, |b + d|)
__device__ __forceinline__ double half_angle(edge_terms e) { return atan2(sqrt(e.m2), sqrt(e.q)); }

// Surface-gradient terms of the edge at b, on the unit sphere (projection on the tangent plane
// left to the caller): the area term w(b, d) = (b x d)/(1 + b.d), which a cell with the edge
// b -> d loses and the cell with d -> b gains, and the length term (b - d)/sin(theta), whose
// tangent part is d theta/db (0 for a zero-length edge).
__device__ __forceinline__ vec3 edge_area_term(edge_terms e) { return (2.0 / fmax(e.q, 1e-300)) * e.x; }
__device__ __forceinline__ vec3 edge_length_term(edge_terms e) {
    return (2.0 / fmax(sqrt(e.m2) * sqrt(e.q), 1e-150)) * e.m;
}
