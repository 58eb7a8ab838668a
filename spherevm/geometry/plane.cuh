// Metric primitives of the periodic plane, the CUDA twin of spherevm/constraints/plane.py: the same
// formulas, the operations in the same order. Points are (x, y, 0), stored in [0, Lx) x [0, Ly) of
// their replica's box; an edge is the minimum image of the difference of its ends, so edges (not
// whole cells) must be shorter than half the box.
#pragma once

#include "geometry/vec3.cuh"

// One replica's box (Lx, Ly), row r of State.box (n_replicas, 2).
struct box2 { double x, y; };

__device__ __forceinline__ box2 load_box(const double* box, long r) { box2 b = {box[2 * r], box[2 * r + 1]}; return b; }

// The image of the in-plane displacement d with components in [-L/2, L/2]: d - L rint(d / L), z
// dropped (minimum_image).
__device__ __forceinline__ vec3 minimum_image(vec3 d, box2 b) {
    return v3(d.x - b.x * rint(d.x / b.x), d.y - b.y * rint(d.y / b.y), 0.0);
}

// x into [0, L): x - L floor(x / L), with L itself (an x just below 0 rounds up to it) taken to 0.
__device__ __forceinline__ double wrap_coordinate(double x, double L) {
    double w = x - L * floor(x / L);
    return w >= L ? w - L : w;
}

// P_N of the plane: z = 0 and x, y wrapped into the box (PeriodicPlane.project_normal).
__device__ __forceinline__ vec3 wrap_into_box(vec3 x, box2 b) {
    return v3(wrap_coordinate(x.x, b.x), wrap_coordinate(x.y, b.y), 0.0);
}

// The edge from a to b: the minimum image of b - a; its length.
__device__ __forceinline__ vec3 plane_edge(vec3 a, vec3 b, box2 box) { return minimum_image(b - a, box); }
__device__ __forceinline__ double plane_length2(vec3 e) { return e.x * e.x + e.y * e.y; }
__device__ __forceinline__ double plane_length(vec3 e) { return sqrt(e.x * e.x + e.y * e.y); }

// b as seen from a: the image of b nearest a (PeriodicPlane.unwrap), z = 0.
__device__ __forceinline__ vec3 plane_unwrap(vec3 b, vec3 a, box2 box) {
    vec3 d = minimum_image(b - a, box);
    return v3(a.x + d.x, a.y + d.y, 0.0);
}

// Area (shoelace) and perimeter of the cell row[0 .. n-1] (counter-clockwise), the polygon unwrapped
// edge by edge from its first vertex (PeriodicPlane.cell_geometry): with e_j the minimum-image edge
// from vertex j to vertex j + 1, vertex j sits at r_j = sum_{i<j} e_i, formed as NumPy's
// running sum minus e_j as NumPy forms it; A = 1/2 sum_j r_j x e_j and P = sum_j |e_j|, summed in
// slot order as NumPy sums them. Compiled without contraction (the host harness, -ffp-contract=off)
// this is NumPy bit for bit; nvcc fuses multiply-adds, so the GPU agrees to rounding.
__device__ __forceinline__ void plane_cell_measures(const double* pos, const int* row, int n, box2 box,
                                                    double* area, double* perimeter) {
    vec3 first = load3(pos, row[0]);
    vec3 a = first;
    double sx = 0.0, sy = 0.0, twice_area = 0.0, length = 0.0;
    for (int i = 0; i < n; ++i) {
        vec3 b = i + 1 < n ? load3(pos, row[i + 1]) : first;
        vec3 e = plane_edge(a, b, box);
        sx += e.x;
        sy += e.y;
        double rx = sx - e.x, ry = sy - e.y;
        twice_area += rx * e.y - ry * e.x;
        length += plane_length(e);
        a = b;
    }
    *area = 0.5 * twice_area;
    *perimeter = length;
}

// What the edge e from a vertex to a neighbour adds to the gradient, at that vertex, of
// sum_c a_c A_c + p_c P_c, with `next` the cell after e and `prev` the cell before it counter-clockwise
// about the vertex (PeriodicPlane.shape_gradient): the shoelace part alpha rot(e), rot(x, y) = (y, -x),
// alpha = (a_next - a_prev) / 2, and the perimeter part -beta e, beta = (p_next + p_prev) / |e|
// (0 for a zero-length edge).
__device__ __forceinline__ vec3 plane_edge_gradient(vec3 e, double a_next, double a_prev, double p_next,
                                                    double p_prev) {
    double alpha = 0.5 * (a_next - a_prev);
    double beta = (p_next + p_prev) / fmax(plane_length(e), 1e-300);
    return v3(alpha * e.y - beta * e.x, -alpha * e.x - beta * e.y, 0.0);
}

// The gradient at vertex v of sum_c a_c A_c + p_c P_c, coef[2 c] = a_c and coef[2 c + 1] = p_c: its
// edges to vn[3 v + j], with cell vc[3 v + j] after edge j and vc[3 v + j - 1] before it, summed in
// slot order. z = 0.
__device__ __forceinline__ vec3 plane_vertex_gradient(const double* pos, const int* vn, const int* vc, long v,
                                                      box2 box, const double* coef) {
    vec3 x = load3(pos, v);
    vec3 g = v3(0.0, 0.0, 0.0);
    for (int j = 0; j < 3; ++j) {
        int c_next = vc[3 * v + j], c_prev = vc[3 * v + (j + 2) % 3];
        vec3 e = plane_edge(x, load3(pos, vn[3 * v + j]), box);
        g = g + plane_edge_gradient(e, coef[2 * c_next], coef[2 * c_prev], coef[2 * c_next + 1], coef[2 * c_prev + 1]);
    }
    return g;
}
