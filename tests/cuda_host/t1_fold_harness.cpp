// tests/cuda_host/t1_fold_harness.cpp -- extern "C" wrappers that run spherevm/plugins/updaters/t1_fold.cuh
// (the T1 flip's geometry and fold rule, as t1_detect and t1_apply use them) on the CPU. Built and
// loaded by tests/test_t1_fold.py exactly as harness.cpp is by tests/test_cuda_headers.py.
#include "cuda_host.h"

#include "plugins/updaters/t1_fold.cuh"

extern "C" {

// per candidate: positions of u, v, a, b, c, d (n, 3 each), radius and new length (n,) -> px, py (n, 3)
void h_t1_new_positions(long n, const double* pu, const double* pv, const double* pa, const double* pb,
                        const double* pc, const double* pd, const double* radius, const double* full,
                        double* px, double* py)
{
    for (long i = 0; i < n; ++i) {
        vec3 x, y;
        t1_new_positions(load3(pu, i), load3(pv, i), load3(pa, i), load3(pb, i), load3(pc, i), load3(pd, i),
                         radius[i], full[i], &x, &y);
        store3(px, i, x);
        store3(py, i, y);
    }
}

// cand (n, 10): u, v, a, b, c, d, C1, C2, C3, C4; px, py (n, 3) -> fold (n,) 0 or 1
void h_t1_would_fold(long n, const double* pos, const int* vn, const int* cell_vertices, const int* sides,
                     int max_sides, const int* cand, const double* px, const double* py, int* fold)
{
    for (long i = 0; i < n; ++i) {
        const int* e = cand + 10 * i;
        fold[i] = t1_would_fold(pos, vn, cell_vertices, sides, max_sides, e[0], e[1], e[2], e[3], e[4], e[5], e[6],
                                e[7], e[8], e[9], load3(px, i), load3(py, i)) ? 1 : 0;
    }
}

}  // extern "C"
