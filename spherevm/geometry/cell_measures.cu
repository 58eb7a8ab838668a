// Every cell's area and perimeter, one thread a cell (spherevm.constraints.kernels.cell_measures):
// the vertex model's Surface::cell_measures, so the shapes the GPU reports are the ones its energy sees.
#include "geometry/surface.cuh"

extern "C" __global__ void cell_measures(const double* __restrict__ pos, const int* __restrict__ cell_vertices,
                                         const int* __restrict__ cell_sides, const int* __restrict__ cell_replica,
                                         const double* __restrict__ size, int n_cells, int max_sides,
                                         double* __restrict__ area, double* __restrict__ perimeter)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    Surface::cell_measures(pos, cell_vertices + c * max_sides, cell_sides[c], Surface::size(size, cell_replica[c]),
                           area + c, perimeter + c);
}

// Sets *open (a word of the replica summary, spherevm.simplicity.flag_open_cells) if a cell's
// minimum-image edges (Surface::delta) do not add up to zero, relative to its box side
// (Surface::period), within `tolerance` (simplicity.open_cells): an edge of it reached half the box.
// One thread a cell; nothing on a surface without images (Surface::periodic false).
template <class S>
__device__ __forceinline__ void open_cell(const double* pos, const int* row, int n, typename S::Size s,
                                          double tolerance, unsigned long long* open)
{
    if constexpr (S::periodic) {
        auto b = S::period(s);
        vec3 sum = v3(0.0, 0.0, 0.0);
        for (int j = 0; j < n; ++j)
            sum = sum + S::delta(load3(pos, row[j]), load3(pos, row[j + 1 < n ? j + 1 : 0]), s);
        if (fabs(sum.x) / b.x > tolerance || fabs(sum.y) / b.y > tolerance) *open = 1ull;
    }
}

extern "C" __global__ void open_cells(const double* __restrict__ pos, const int* __restrict__ cell_vertices,
                                      const int* __restrict__ cell_sides, const int* __restrict__ cell_replica,
                                      const double* __restrict__ size, int n_cells, int max_sides, double tolerance,
                                      unsigned long long* __restrict__ open)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    const int* row = cell_vertices + c * max_sides;
    int n = cell_sides[c];
    Surface::Size s = Surface::size(size, cell_replica[c]);
    open_cell<Surface>(pos, row, n, s, tolerance, open);
}
