// tests/cuda_host/harness.cpp -- extern "C" wrappers that run spherevm's device headers on the CPU.
//
// Built by tests/test_cuda_headers.py at test time:
//   g++ -O2 -std=c++17 -shared -fPIC -ffp-contract=off -I<repo>/spherevm -I<here> harness.cpp
// and loaded with ctypes. Every function loops over n items and calls one header function per
// item, exactly as a kernel thread would; arrays are C-contiguous (n, 3) doubles for vectors.
#include "cuda_host.h"

#include "random_philox.cuh"
#include "constraints/sphere.cuh"   // the two Surface structs (and geometry/sphere.cuh, geometry/plane.cuh)
#include "constraints/plane.cuh"

typedef unsigned int u32;
typedef unsigned long long u64;

extern "C" {

// ------------------------------------------------------------------------------ Philox
// ctr (n, 4), key (n, 2) -> out (n, 4): svm_philox4x32_10 when rounds == 10, else svm_philox4x32_R.
void h_philox4x32(long n, u32 rounds, const u32* ctr, const u32* key, u32* out)
{
    for (long i = 0; i < n; ++i) {
        const uint4 c = make_uint4(ctr[4 * i], ctr[4 * i + 1], ctr[4 * i + 2], ctr[4 * i + 3]);
        const uint2 k = make_uint2(key[2 * i], key[2 * i + 1]);
        const uint4 w = rounds == 10u ? svm_philox4x32_10(c, k) : svm_philox4x32_R(rounds, c, k);
        out[4 * i] = w.x; out[4 * i + 1] = w.y; out[4 * i + 2] = w.z; out[4 * i + 3] = w.w;
    }
}

// svm_rng_block for ids (n,) and blocks 0 .. nblocks-1 -> out (n, nblocks, 4)
void h_rng_block(u32 seed, u32 stream, u64 timestep, long n, const u32* ids, u32 nblocks, u32* out)
{
    for (long i = 0; i < n; ++i)
        for (u32 b = 0; b < nblocks; ++b) {
            const uint4 w = svm_rng_block(seed, stream, timestep, ids[i], b);
            u32* o = out + 4 * (i * (long)nblocks + b);
            o[0] = w.x; o[1] = w.y; o[2] = w.z; o[3] = w.w;
        }
}

// svm_u01 on word pairs (n,) -> (n,)
void h_u01(long n, const u32* hi, const u32* lo, double* out)
{
    for (long i = 0; i < n; ++i) out[i] = svm_u01(hi[i], lo[i]);
}

// Draws 0 .. count-1 of each id -> out (n, count). kind: 0 svm_uniform, 1 svm_normal (one call per
// draw), 2 svm_uniform2, 3 svm_normal2 (one call per block, as the kernels use them).
void h_draws(int kind, u32 seed, u32 stream, u64 timestep, long n, const u32* ids, u32 count, double* out)
{
    for (long i = 0; i < n; ++i) {
        double* o = out + i * (long)count;
        if (kind == 0 || kind == 1) {
            for (u32 j = 0; j < count; ++j)
                o[j] = kind == 0 ? svm_uniform(seed, stream, timestep, ids[i], j)
                                 : svm_normal(seed, stream, timestep, ids[i], j);
        } else {
            for (u32 b = 0; 2 * b < count; ++b) {
                double z0, z1;
                if (kind == 2) svm_uniform2(seed, stream, timestep, ids[i], b, &z0, &z1);
                else svm_normal2(seed, stream, timestep, ids[i], b, &z0, &z1);
                o[2 * b] = z0;
                if (2 * b + 1 < count) o[2 * b + 1] = z1;
            }
        }
    }
}

// ------------------------------------------------------------------------------ sphere geometry
void h_normalize3(long n, const double* a, double* out)
{
    for (long i = 0; i < n; ++i) store3(out, i, normalize3(load3(a, i)));
}

void h_norm3(long n, const double* a, double* out)
{
    for (long i = 0; i < n; ++i) out[i] = norm3(load3(a, i));
}

void h_dot_cross(long n, const double* a, const double* b, double* dot, double* cross)
{
    for (long i = 0; i < n; ++i) {
        dot[i] = dot3(load3(a, i), load3(b, i));
        store3(cross, i, cross3(load3(a, i), load3(b, i)));
    }
}

void h_geodesic_length(long n, const double* a, const double* b, double* out)
{
    for (long i = 0; i < n; ++i) out[i] = geodesic_length(load3(a, i), load3(b, i));
}

void h_geodesic_length_gradient(long n, const double* a, const double* b, double* out)
{
    for (long i = 0; i < n; ++i) store3(out, i, geodesic_length_gradient(load3(a, i), load3(b, i)));
}

void h_solid_angle(long n, const double* a, const double* b, const double* c, double* out)
{
    for (long i = 0; i < n; ++i) out[i] = solid_angle(load3(a, i), load3(b, i), load3(c, i));
}

void h_solid_angle_gradient(long n, const double* a, const double* b, const double* c, double* out)
{
    for (long i = 0; i < n; ++i)
        store3(out, i, solid_angle_gradient(load3(a, i), load3(b, i), load3(c, i)));
}

// make_edge(b, d) and what the force kernel takes from it: m (n, 3), x (n, 3), m2, q, half_angle,
// edge_area_term (n, 3), edge_length_term (n, 3).
void h_edge(long n, const double* b, const double* d, double* m, double* x, double* m2, double* q,
            double* half, double* area, double* length)
{
    for (long i = 0; i < n; ++i) {
        const edge_terms e = make_edge(load3(b, i), load3(d, i));
        store3(m, i, e.m);
        store3(x, i, e.x);
        m2[i] = e.m2;
        q[i] = e.q;
        half[i] = half_angle(e);
        store3(area, i, edge_area_term(e));
        store3(length, i, edge_length_term(e));
    }
}

// ------------------------------------------------------------------------------ plane geometry
// minimum_image(d) and wrap_into_box(x) of (n, 3) points, each with its own box (n, 2)
void h_plane_image_wrap(long n, const double* d, const double* x, const double* box, double* image, double* wrapped)
{
    for (long i = 0; i < n; ++i) {
        const box2 b = load_box(box, i);
        store3(image, i, minimum_image(load3(d, i), b));
        store3(wrapped, i, wrap_into_box(load3(x, i), b));
    }
}

}  // extern "C"

// ------------------------------------------------------------------------------ through Surface
// What the kernels do per cell, vertex or flip, for either surface S; size is the State's radius or
// box. The extern "C" names below are h_<surface>_<what>.
template <class S>
static void surface_cells(long n_cells, const double* pos, const int* cell_vertices, const int* cell_sides,
                          const int* cell_replica, const double* size, int max_sides, double* area,
                          double* perimeter, double* units)
{
    for (long c = 0; c < n_cells; ++c) {
        const typename S::Size s = S::size(size, cell_replica[c]);
        S::cell_measures(pos, cell_vertices + c * max_sides, cell_sides[c], s, area + c, perimeter + c);
        units[2 * c] = S::area_unit(s);
        units[2 * c + 1] = S::length_unit(s);
    }
}

template <class S>
static void surface_forces(long n_vertices, const double* pos, const int* vn, const int* vc, const int* vertex_replica,
                           const double* size, const double* coef, double* forces)
{
    for (long v = 0; v < n_vertices; ++v)
        store3(forces, v, S::vertex_force(pos, vn, vc, v, S::size(size, vertex_replica[v]), coef));
}

// per pair (u[i], v[i]) of replica rep[i]: chord2 and edge_length
template <class S>
static void surface_edges(long n, const double* pos, const int* u, const int* v, const int* rep, const double* size,
                          double* chord2, double* length)
{
    for (long i = 0; i < n; ++i) {
        const typename S::Size s = S::size(size, rep[i]);
        chord2[i] = S::chord2(load3(pos, u[i]), load3(pos, v[i]), s);
        length[i] = S::edge_length(load3(pos, u[i]), load3(pos, v[i]), s);
    }
}

// per point y (n, 3) of replica rep[i]: normal(y) and place(y, normal(y)) (P_N)
template <class S>
static void surface_project(long n, const double* y, const int* rep, const double* size, double* normal, double* placed)
{
    for (long i = 0; i < n; ++i) {
        const vec3 m = S::normal(load3(y, i), S::size(size, rep[i]));
        store3(normal, i, m);
        store3(placed, i, S::place(load3(y, i), m, S::size(size, rep[i])));
    }
}

// per flip, quad (n, 6) = (u, v, a, b, c, d) of replica rep[i], new length full[i]: the new
// positions of X = v and Y = u
template <class S>
static void surface_t1(long n, const double* pos, const int* quad, const int* rep, const double* size,
                       const double* full, double* x_pos, double* y_pos)
{
    for (long i = 0; i < n; ++i) {
        const int* q = quad + 6 * i;
        vec3 x, y;
        S::t1_positions(pos, q[0], q[1], q[2], q[3], q[4], q[5], S::size(size, rep[i]), full[i], &x, &y);
        store3(x_pos, i, x);
        store3(y_pos, i, y);
    }
}

// per cell: cell_normal
template <class S>
static void surface_cell_normals(long n_cells, const double* pos, const int* cell_vertices, const int* cell_sides,
                                 const int* cell_replica, const double* size, int max_sides, double* out)
{
    for (long c = 0; c < n_cells; ++c)
        store3(out, c, S::cell_normal(pos, cell_vertices + c * max_sides, cell_sides[c], S::size(size, cell_replica[c])));
}

#define EXPORT_SURFACE(NAME, S)                                                                                     \
    extern "C" void h_##NAME##_cells(long n, const double* p, const int* cv, const int* cs, const int* cr,              \
                                     const double* sz, int ms, double* a, double* per, double* u)                     \
    { surface_cells<S>(n, p, cv, cs, cr, sz, ms, a, per, u); }                                                      \
    extern "C" void h_##NAME##_forces(long n, const double* p, const int* vn, const int* vc, const int* vr,             \
                                      const double* sz, const double* coef, double* f)                                \
    { surface_forces<S>(n, p, vn, vc, vr, sz, coef, f); }                                                           \
    extern "C" void h_##NAME##_edges(long n, const double* p, const int* u, const int* v, const int* r,               \
                                     const double* sz, double* c2, double* len)                                       \
    { surface_edges<S>(n, p, u, v, r, sz, c2, len); }                                                               \
    extern "C" void h_##NAME##_project(long n, const double* y, const int* r, const double* sz, double* nrm,          \
                                       double* placed)                                                                \
    { surface_project<S>(n, y, r, sz, nrm, placed); }                                                               \
    extern "C" void h_##NAME##_t1(long n, const double* p, const int* q, const int* r, const double* sz,              \
                                  const double* full, double* x, double* y)                                           \
    { surface_t1<S>(n, p, q, r, sz, full, x, y); }                                                                  \
    extern "C" void h_##NAME##_cell_normals(long n, const double* p, const int* cv, const int* cs, const int* cr,     \
                                            const double* sz, int ms, double* o)                                      \
    { surface_cell_normals<S>(n, p, cv, cs, cr, sz, ms, o); }

EXPORT_SURFACE(sphere, SphereSurface)
EXPORT_SURFACE(plane, PlaneSurface)
