// Three-vectors of doubles for spherevm's kernels (positions, forces and velocities are (n, 3)
// arrays). Shared by the surface headers geometry/sphere.cuh and geometry/plane.cuh.
#pragma once

struct vec3 { double x, y, z; };

__device__ __forceinline__ vec3 v3(double x, double y, double z) { vec3 r = {x, y, z}; return r; }
__device__ __forceinline__ vec3 operator+(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
__device__ __forceinline__ vec3 operator-(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
__device__ __forceinline__ vec3 operator-(vec3 a) { return v3(-a.x, -a.y, -a.z); }
__device__ __forceinline__ vec3 operator*(double s, vec3 a) { return v3(s * a.x, s * a.y, s * a.z); }
// The compiler may fuse multiply-adds and normalisation uses rsqrt (about 1 ulp), so results agree
// with NumPy to rounding (the tests ask 1e-12 relative).
__device__ __forceinline__ double dot3(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
__device__ __forceinline__ vec3 cross3(vec3 a, vec3 b) {
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
__device__ __forceinline__ double norm3(vec3 a) { return sqrt(dot3(a, a)); }
__device__ __forceinline__ vec3 normalize3(vec3 a) { double s = rsqrt(dot3(a, a)); return s * a; }
__device__ __forceinline__ vec3 load3(const double* p, long i) { return v3(p[3 * i], p[3 * i + 1], p[3 * i + 2]); }
__device__ __forceinline__ void store3(double* p, long i, vec3 a) { p[3 * i] = a.x; p[3 * i + 1] = a.y; p[3 * i + 2] = a.z; }

// a x + y, a x and x + y with each operation rounded as written: neither the compiler nor ptxas may
// fuse or split them, so code that must give the same bits wherever it is inlined (FIRE's move,
// plugins/integrators/fire.cuh) writes its arithmetic out with them.
__device__ __forceinline__ vec3 fma3_rn(double a, vec3 x, vec3 y) {
    return v3(__fma_rn(a, x.x, y.x), __fma_rn(a, x.y, y.y), __fma_rn(a, x.z, y.z));
}
__device__ __forceinline__ vec3 mul3_rn(double a, vec3 x) {
    return v3(__dmul_rn(a, x.x), __dmul_rn(a, x.y), __dmul_rn(a, x.z));
}
__device__ __forceinline__ vec3 add3_rn(vec3 x, vec3 y) {
    return v3(__dadd_rn(x.x, y.x), __dadd_rn(x.y, y.y), __dadd_rn(x.z, y.z));
}
// a.b and a x b, rounded as written (the products of a cross product's component both feed one
// subtraction, so ptxas may otherwise fuse either one, and chooses by the code around it).
__device__ __forceinline__ double dot3_rn(vec3 a, vec3 b) {
    return __fma_rn(a.z, b.z, __fma_rn(a.x, b.x, __dmul_rn(a.y, b.y)));
}
__device__ __forceinline__ vec3 cross3_rn(vec3 a, vec3 b) {
    return v3(__fma_rn(a.y, b.z, -__dmul_rn(a.z, b.y)), __fma_rn(a.z, b.x, -__dmul_rn(a.x, b.z)),
              __fma_rn(a.x, b.y, -__dmul_rn(a.y, b.x)));
}
