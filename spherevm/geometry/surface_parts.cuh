// What every surface's device code shares (geometry/surface.cuh lists the functions a surface gives):
// the empty extra of a force fused into the vertex model and the two ways to get 1 / |x|.
#pragma once

#include "geometry/vec3.cuh"

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
