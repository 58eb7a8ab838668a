// The geometry of a T1 flip on the sphere, shared by t1_detect and t1_apply (t1.cu): where the two
// vertices go, and whether the flip would fold the network. The CUDA twin of
// spherevm.topology.t1_new_positions and spherevm.folding.t1_folds, the same arithmetic in the
// same order (compiled on the CPU and compared with them by tests/test_t1_fold.py). Names as in
// topology.t1_cells:
// C1 = (.., a, u, v, d, ..), C2 = (.., c, v, u, b, ..), C3 = (.., b, u, a, ..), C4 = (.., d, v, c, ..);
// after the flip X = v sits on the C1 side with row (Y, d, a), Y = u on the C2 side with (X, b, c).
#pragma once
#include "geometry/sphere.cuh"

// Rotate the edge u-v about the normal at its midpoint: *px (C1 side) and *py `full` apart.
__device__ __forceinline__ void t1_new_positions(vec3 pu, vec3 pv, vec3 pa, vec3 pb, vec3 pc, vec3 pd, double R,
                                                 double full, vec3* px, vec3* py)
{
    vec3 mid = R * normalize3(0.5 * (pu + pv));
    vec3 nrm = normalize3(mid);
    vec3 w = pv - pu;
    vec3 along = w - dot3(w, nrm) * nrm;
    double len = norm3(along);
    vec3 perp;
    if (len <= 1e-12 * R) {     // a zero-length edge has no direction: across the cells' sides
        vec3 s = 0.5 * (pa + pd) - 0.5 * (pb + pc);
        perp = s - dot3(s, nrm) * nrm;
    } else {
        perp = cross3(nrm, v3(along.x / len, along.y / len, along.z / len));
    }
    perp = normalize3(perp);
    double phi = 0.5 * full / R;
    vec3 m = normalize3(mid);
    *px = R * (cos(phi) * m + sin(phi) * perp);
    *py = R * (cos(phi) * m + sin(phi) * (-perp));
}

// An inverted corner at w: its edges to n0, n1, n2 (its row, counter-clockwise in a valid network)
// turn clockwise, i.e. two of the three turns between consecutive edges are negative.
__device__ __forceinline__ bool t1_inverted(vec3 w, vec3 n0, vec3 n1, vec3 n2)
{
    vec3 nrm = normalize3(w);
    vec3 e0 = n0 - w, e1 = n1 - w, e2 = n2 - w;
    int negative = (dot3(nrm, cross3(e0, e1)) < 0.0 ? 1 : 0) + (dot3(nrm, cross3(e1, e2)) < 0.0 ? 1 : 0)
                 + (dot3(nrm, cross3(e2, e0)) < 0.0 ? 1 : 0);
    return negative >= 2;
}

// w's row now (moved < 0) or with the neighbour `moved` at `at`: is the corner inverted?
__device__ __forceinline__ bool t1_row_inverted(const double* pos, const int* vn, int w, int moved, vec3 at)
{
    vec3 n[3];
    for (int k = 0; k < 3; ++k) n[k] = vn[3 * w + k] == moved ? at : load3(pos, vn[3 * w + k]);
    return t1_inverted(load3(pos, w), n[0], n[1], n[2]);
}

// Signed solid angle of a cell after the flip, as the force will measure it: the fan about its
// first vertex after the flip (`moved` if the row starts with u or v) over its edges that do not
// touch u or v, in row order, then its new edges along the chain ends[0..m).
__device__ __forceinline__ double t1_area_after(const double* pos, const int* row, int n, int u, int v,
                                                vec3 moved, const vec3* ends, int m)
{
    vec3 apex = normalize3(row[0] == u || row[0] == v ? moved : load3(pos, row[0]));
    double area = 0.0;
    for (int j = 0; j < n; ++j) {
        int p = row[j], q = row[j + 1 < n ? j + 1 : 0];
        if (p == u || p == v || q == u || q == v) continue;
        area += solid_angle(apex, normalize3(load3(pos, p)), normalize3(load3(pos, q)));
    }
    for (int k = 0; k + 1 < m; ++k) area += solid_angle(apex, normalize3(ends[k]), normalize3(ends[k + 1]));
    return area;
}

// Would flipping u-v (new places px, py) fold the network? One of the four cells with signed area
// <= 0 afterwards, or a corner of u, v, a, b, c, d inverted that was not inverted before.
__device__ __forceinline__ bool t1_would_fold(const double* pos, const int* vn, const int* cell_vertices,
                                              const int* sides, int max_sides, int u, int v, int a, int b, int c,
                                              int d, int C1, int C2, int C3, int C4, vec3 px, vec3 py)
{
    vec3 pa = load3(pos, a), pb = load3(pos, b), pc = load3(pos, c), pd = load3(pos, d);
    vec3 e1[3] = {pa, px, pd}, e2[3] = {pc, py, pb}, e3[4] = {pb, py, px, pa}, e4[4] = {pd, px, py, pc};
    if (!(t1_area_after(pos, cell_vertices + (long)C1 * max_sides, sides[C1], u, v, px, e1, 3) > 0.0)) return true;
    if (!(t1_area_after(pos, cell_vertices + (long)C2 * max_sides, sides[C2], u, v, py, e2, 3) > 0.0)) return true;
    if (!(t1_area_after(pos, cell_vertices + (long)C3 * max_sides, sides[C3], u, v, py, e3, 4) > 0.0)) return true;
    if (!(t1_area_after(pos, cell_vertices + (long)C4 * max_sides, sides[C4], u, v, px, e4, 4) > 0.0)) return true;
    if (t1_inverted(px, py, pd, pa) && !t1_row_inverted(pos, vn, v, -1, px)) return true;
    if (t1_inverted(py, px, pb, pc) && !t1_row_inverted(pos, vn, u, -1, py)) return true;
    if (t1_row_inverted(pos, vn, a, u, px) && !t1_row_inverted(pos, vn, a, -1, px)) return true;
    if (t1_row_inverted(pos, vn, d, v, px) && !t1_row_inverted(pos, vn, d, -1, px)) return true;
    if (t1_row_inverted(pos, vn, b, u, py) && !t1_row_inverted(pos, vn, b, -1, py)) return true;
    if (t1_row_inverted(pos, vn, c, v, py) && !t1_row_inverted(pos, vn, c, -1, py)) return true;
    return false;
}
