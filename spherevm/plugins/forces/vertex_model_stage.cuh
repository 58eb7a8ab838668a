// The vertex model's stage of the fused small-tissue steps (spherevm/tissue_steps.cu,
// VertexModel.fused_stage): a cell's two coefficients from its area and perimeter (vm_cell_terms)
// and a vertex's force from its cells' coefficients (Surface::vertex_force), the functions of the
// general kernels (vertex_model.cu), so the fused forces are theirs bit for bit. VertexModelArgs is
// declared from its Python definition (VertexModel.FUSED_ARGS): the per-cell kA, kP, A0, P0. Its vertex
// part takes an extra (FusedStage.takes_extra): a force joined into it (Force.fused_combined, the
// bending force's stage) adds its gradient before the projection, as in the general kernels that
// Force.combined runs.
#pragma once
#include "plugins/forces/vertex_model.cuh"

struct VertexModelStage {
    // coef: 2 kA (A - A0) and 2 kP (P - P0), in surface units; on flat facets (dE/dA a / A, dE/dP)
    static constexpr int cell_doubles = Surface::coef_width;
    static constexpr bool measures = true;     // takes each cell's area and perimeter
    VertexModelArgs a;

    // on flat facets (Surface::coef_width 4) the cell's vector area too: vm_cell measures it again
    __device__ __forceinline__ void cell(double A, double P, long c, Surface::Size s, double* coef, const double* pos,
                                         const int* row, int n) const
    {
        if constexpr (Surface::coef_width == 2)
            vm_cell_terms(A, P, c, s, a.kA, a.kP, a.A0, a.P0, coef);
        else
            vm_cell<Surface>(pos, row, n, c, s, a.kA, a.kP, a.A0, a.P0, coef, NoExtra());
    }

    template <class Extra = NoExtra>
    __device__ __forceinline__ vec3 vertex(const double* pos, const int* vn, const int* vc, long v, Surface::Size s,
                                           const double* coef, KeptNorm norm, const Extra& extra = Extra()) const
    {
        return Surface::vertex_force(pos, vn, vc, v, s, coef, extra, norm);
    }
};
