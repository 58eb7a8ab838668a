// The bending force's stage of the fused small-tissue steps (spherevm/tissue_steps.cu,
// Bending.fused_stage and Bending.fused_combined): bending.cuh's functions, as its general kernels
// (bending.cu) call them, so the fused forces are theirs bit for bit. Its parts: each cell's unit
// normal and 1/|2a| (cell: 4 doubles a cell), then, once every cell's normal is known, each cell's
// w = (dE/da) / 2 over its neighbours (neighbours: 3 doubles a cell), then each vertex's force
// (vertex: bending alone) or its gradient added inside the vertex model's vertex force (add_gradient:
// an extra of the vertex model's stage, as vm_bending_vertex_forces adds it). BendingArgs is declared
// from its Python definition (Bending.FUSED_ARGS): B per cell.
#pragma once
#include "plugins/forces/bending.cuh"

struct BendingStage {
    static constexpr int cell_doubles = 4;        // the unit normal, 1 / |2 a|
    static constexpr int neighbour_doubles = 3;   // w = (dE/da) / 2
    static constexpr bool measures = true;        // (a cell part; its area and perimeter are not used)
    BendingArgs a;

    __device__ static __forceinline__ vec3 normal(const double* coef, long c)
    {
        return v3(coef[4 * c], coef[4 * c + 1], coef[4 * c + 2]);
    }

    __device__ __forceinline__ void cell(double, double, long c, Surface::Size, double* coef, const double* pos,
                                         const int* row, int n) const
    {
        vec3 m;
        bending_cell_normal(pos, row, n, &m, coef + 4 * c + 3);
        coef[4 * c] = m.x;
        coef[4 * c + 1] = m.y;
        coef[4 * c + 2] = m.z;
    }

    __device__ __forceinline__ void neighbours(const double*, const int* vc, const int* cell_vertices,
                                               const int* sides, int max_sides, long c, Surface::Size,
                                               const double* coef, double* more) const
    {
        const vec3 ni = normal(coef, c);
        double sq;
        vec3 s = bending_neighbour_sum([&](int j) { return normal(coef, j); }, cell_vertices + c * max_sides, sides[c],
                                       vc, c, ni, &sq);
        store3(more, c, bending_w(s, ni, a.B[c], coef[4 * c + 3]));
    }

    __device__ __forceinline__ void add_gradient(vec3& g, const double* pos, const int* vn, const int* vc, long v,
                                                 vec3 x, const double*, const double* more) const
    {
        bending_gradient(g, pos, vn, vc, v, x, more);
    }

    __device__ __forceinline__ vec3 vertex(const double* pos, const int* vn, const int* vc, long v, Surface::Size,
                                           const double*, const double* more, KeptNorm) const
    {
        return bending_vertex_force(pos, vn, vc, v, more);
    }
};
