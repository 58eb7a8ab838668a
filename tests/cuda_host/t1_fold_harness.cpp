// tests/cuda_host/t1_fold_harness.cpp -- extern "C" wrappers that run spherevm/plugins/updaters/t1_fold.cuh
// (its fold rule and its bow-tie test) and Surface::t1_positions (geometry/surface.cuh), as t1_detect
// uses them, on the CPU. Built and
// loaded by tests/test_t1_fold.py as harness.cpp is by tests/test_cuda_headers.py, once per surface
// (t1_fold_harness_plane.cpp names the plane's surface first).
#include "cuda_host.h"
#ifndef SVM_SURFACE   // the sphere, unless a wrapper named another surface (as surface_kernels does)
#include "constraints/sphere.cuh"
#define SVM_SURFACE SphereSurface
#endif

#include "plugins/updaters/t1_fold.cuh"

extern "C" {

// cand (n, 10): u, v, a, b, c, d, C1, C2, C3, C4; size: each candidate's radius (n,) or box (n, 2);
// full (n,): the new lengths; turn: rotate the other way (0 or 1) -> px, py (n, 3)
void h_t1_positions(long n, const double* pos, const int* cand, const double* size, const double* full,
                    int turn, double* px, double* py)
{
    for (long i = 0; i < n; ++i) {
        const int* e = cand + 10 * i;
        vec3 x, y;
        Surface::t1_positions(pos, e[0], e[1], e[2], e[3], e[4], e[5], Surface::size(size, i), full[i], &x, &y,
                              turn != 0);
        store3(px, i, x);
        store3(py, i, y);
    }
}

// -> level (n,): t1_fold_level at the places px, py
void h_t1_fold_level(long n, const double* pos, const int* vn, const int* cell_vertices, const int* sides,
                     int max_sides, const int* cand, const double* size, const double* px, const double* py, int* level)
{
    for (long i = 0; i < n; ++i) {
        const int* e = cand + 10 * i;
        level[i] = t1_fold_level(pos, vn, cell_vertices, sides, max_sides, e[0], e[1], e[2], e[3], e[4], e[5], e[6],
                                 e[7], e[8], e[9], load3(px, i), load3(py, i), Surface::size(size, i));
    }
}

// -> crossed (n,): t1_bow_tie of each candidate's edge u v, 1 where it is turned past zero length
void h_t1_bow_tie(long n, const double* pos, const int* cand, const double* size, int* crossed)
{
    for (long i = 0; i < n; ++i) {
        const int* e = cand + 10 * i;
        crossed[i] = t1_bow_tie(pos, load3(pos, e[0]), load3(pos, e[1]), e[2], e[3], e[4], e[5],
                                Surface::size(size, i)) ? 1 : 0;
    }
}

}  // extern "C"
