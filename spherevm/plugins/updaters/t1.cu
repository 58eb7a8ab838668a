// T1 neighbour exchanges on the device: the CUDA path of t1.py, same rules and same geometry.
// A pass is three kernels: t1_detect (one thread per vertex, its edges to higher-numbered
// neighbours) lists the short edges; t1_check (one thread per listed edge) applies the refusal
// rules and lets each remaining candidate claim its four cells (lowest edge index wins); after one
// small read-back of the counters, t1_apply (one thread per candidate) flips the winners and gives
// back the cells each candidate holds. Winners touch disjoint cells and vertices, so they need no locks.
// The checks are a kernel of their own because they are long (t1_fold.cuh): inside t1_detect their
// registers slowed the short-edge test of every vertex (356 us of a 1e6-cell step on an H200).
// Compiled once per surface (geometry/surface.cuh): the short-edge test and the new positions are
// the surface's. A candidate whose flip would fold the network (t1_fold.cuh) turns the other way
// if that does not fold it, and is refused otherwise (folding.t1_placement).
#include "geometry/surface.cuh"
#include "plugins/updaters/t1_fold.cuh"

#define CAND_INTS 13   // u, k, v, a, b, c, d, C1, C2, C3, C4, replica, turn
#define LOG_INTS 6     // pass, C1, C2, C3, C4, replica

// counters: [0] short edges listed (candidates), [1] a C3/C4 row of a candidate that was not refused
// has width[0] entries (widen the table), [2] candidates not refused (claimants; t1_check).
// width[0]: the table's width as the step-by-step path holds it (inside a CUDA graph the table has
// spare columns beyond it, max_sides is the stride). size: the State's radius or box.
// A candidate's entry: u, k, v, a, b, c, d, C1, C2, C3, C4, replica, and (set by t1_check) turn.
// log_pass: the pass's number in the flip log, counted since the log was last replayed (here, so
// that every thread of t1_apply, a later kernel, reads the same one).
extern "C" __global__ void t1_detect(
    const double* __restrict__ pos, const int* __restrict__ vn, const int* __restrict__ vc,
    const int* __restrict__ vertex_replica, const double* __restrict__ size, const double* __restrict__ chord2,
    const bool* __restrict__ active, int n_vertices, int* __restrict__ counters, int* __restrict__ cand,
    double* __restrict__ cand_len, int capacity, int* __restrict__ log_pass)
{
    int u = blockIdx.x * blockDim.x + threadIdx.x;
    if (u == 0) *log_pass += 1;
    if (u >= n_vertices) return;
    int r = vertex_replica[u];
    if (!active[r]) return;
    Surface::Size s = Surface::size(size, r);
    vec3 pu = load3(pos, u);
    for (int k = 0; k < 3; ++k) {
        int v = vn[3 * u + k];
        if (v <= u) continue;
        vec3 pv = load3(pos, v);
        if (!(Surface::chord2(pu, pv, s) < chord2[r])) continue;   // chord test: no trigonometry for the many long edges
        int i = atomicAdd(counters, 1);
        if (i >= capacity) continue;
        int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        int j = vn[3 * v] == u ? 0 : (vn[3 * v + 1] == u ? 1 : 2);
        int* e = cand + (long)i * CAND_INTS;
        e[0] = u; e[1] = k; e[2] = v; e[3] = vn[3 * u + k1]; e[4] = vn[3 * u + k2];
        e[5] = vn[3 * v + (j + 1) % 3]; e[6] = vn[3 * v + (j + 2) % 3];
        e[7] = vc[3 * u + k]; e[8] = vc[3 * u + k2]; e[9] = vc[3 * u + k1]; e[10] = vc[3 * v + (j + 1) % 3];
        e[11] = r; e[12] = 0;
        cand_len[i] = Surface::edge_length(pu, pv, s);
    }
}

// One thread per slot (n_slots: the room; the candidate count is read here, counters[0]). The rules
// of T1.select: refuse a flip that leaves a triangle with two sides or joins a cell to itself, place
// it as folding.t1_placement does (usual, else turned, else refused if it folds), and let each
// remaining candidate claim its four cells.
// new_length[r] > 0: absolute new length per replica; else length_factor times the old length.
extern "C" __global__ void t1_check(
    const double* __restrict__ pos, const int* __restrict__ vn, const int* __restrict__ sides,
    const int* __restrict__ cell_vertices, const double* __restrict__ size, const double* __restrict__ new_length,
    double length_factor, int max_sides, int* __restrict__ claim, int* __restrict__ refused,
    unsigned long long* __restrict__ total_refused, int* __restrict__ counters, int* __restrict__ cand,
    const double* __restrict__ cand_len, int n_slots, const int* __restrict__ width)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n_slots || i >= counters[0]) return;
    int* e = cand + (long)i * CAND_INTS;
    int u = e[0], k = e[1], v = e[2], a = e[3], b = e[4], c = e[5], d = e[6];
    int C1 = e[7], C2 = e[8], C3 = e[9], C4 = e[10], r = e[11];
    Surface::Size s = Surface::size(size, r);
    bool distinct = C1 != C2 && C1 != C3 && C1 != C4 && C2 != C3 && C2 != C4 && C3 != C4;
    bool refuse = sides[C1] <= 3 || sides[C2] <= 3 || !distinct, turn = false;
    if (!refuse) {      // folding.t1_placement: usual if clean, else turned if clean, else usual unless it folds
        vec3 px, py;
        double full = new_length[r] > 0.0 ? new_length[r] : length_factor * cand_len[i];
        Surface::t1_positions(pos, u, v, a, b, c, d, s, full, &px, &py);
        int usual = t1_fold_level(pos, vn, cell_vertices, sides, max_sides, u, v, a, b, c, d, C1, C2, C3, C4, px,
                                  py, s);
        if (usual != T1_CLEAN) {
            Surface::t1_positions(pos, u, v, a, b, c, d, s, full, &px, &py, true);
            turn = t1_fold_level(pos, vn, cell_vertices, sides, max_sides, u, v, a, b, c, d, C1, C2, C3, C4, px,
                                 py, s) == T1_CLEAN;
            refuse = usual == T1_FOLDS && !turn;
        }
    }
    if (refuse) {       // a refused candidate claims nothing, so t1_apply passes it by
        atomicAdd(refused + r, 1);
        atomicAdd(total_refused + r, 1ull);
        return;
    }
    e[12] = turn ? 1 : 0;
    atomicAdd(counters + 2, 1);
    int index = 3 * u + k;
    atomicMin(claim + C1, index);
    atomicMin(claim + C2, index);
    atomicMin(claim + C3, index);
    atomicMin(claim + C4, index);
    if (sides[C3] >= *width || sides[C4] >= *width) counters[1] = 1;
}

__device__ void replace_neighbor(int* vn, int w, int old_v, int new_v) {
    for (int s = 0; s < 3; ++s)
        if (vn[3 * w + s] == old_v) { vn[3 * w + s] = new_v; return; }
}

__device__ void remove_from_row(int* row, int* n, int x) {
    int p = 0;
    while (row[p] != x) ++p;
    for (int j = p; j < *n - 1; ++j) row[j] = row[j + 1];
    row[*n - 1] = -1;
    *n -= 1;
}

__device__ void split_in_row(int* row, int* n, int x, int first, int second) {
    int p = 0;
    while (row[p] != x) ++p;
    for (int j = *n; j > p + 1; --j) row[j] = row[j - 1];
    row[p] = first;
    row[p + 1] = second;
    *n += 1;
}

// One thread per slot of `moved` (n_slots: the candidate count after the read-back, or the whole
// capacity inside a CUDA graph, where the count is read here: counters[0]). grow_width: inside a graph
// the width the host widens step by step grows here.
// new_length[r] > 0: absolute new length per replica; else length_factor times the old length.
extern "C" __global__ void t1_apply(
    double* __restrict__ pos, int* __restrict__ vn, int* __restrict__ vc, int* __restrict__ cell_vertices,
    int* __restrict__ sides, int* __restrict__ claim, const int* __restrict__ cand,
    const double* __restrict__ cand_len, const int* __restrict__ counters, int n_slots, int max_sides,
    const double* __restrict__ size, const double* __restrict__ new_length, double length_factor,
    int* __restrict__ flips, unsigned long long* __restrict__ total_flips, int* __restrict__ moved,
    int* __restrict__ log_count, int* __restrict__ log, int logging, const int* __restrict__ log_pass,
    int* __restrict__ width, int grow_width)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n_slots) return;
    if (grow_width && i == 0 && counters[1]) *width += 1;
    moved[2 * i] = -1;
    moved[2 * i + 1] = -1;
    if (i >= counters[0]) return;
    const int* e = cand + (long)i * CAND_INTS;
    int u = e[0], k = e[1], v = e[2], a = e[3], b = e[4], c = e[5], d = e[6];
    int C1 = e[7], C2 = e[8], C3 = e[9], C4 = e[10], r = e[11];
    // the claims decide, then this candidate gives back the cells it holds (claims stay at INT_MAX
    // between passes, so a pass costs no sweep over all cells): a cell is held by one candidate, whose
    // thread alone resets it after reading it, so no other thread's decision can change
    int index = 3 * u + k, cells[4] = {C1, C2, C3, C4};
    bool mine[4], won = true;
    for (int j = 0; j < 4; ++j) { mine[j] = claim[cells[j]] == index; won = won && mine[j]; }
    for (int j = 0; j < 4; ++j) if (mine[j]) claim[cells[j]] = 0x7fffffff;
    if (!won) return;
    if (sides[C3] >= max_sides || sides[C4] >= max_sides) return;   // cannot happen: the table was widened
    int X = v, Y = u;   // counter-clockwise rotation: v ends up on the C1 side
    vn[3 * X] = Y; vn[3 * X + 1] = d; vn[3 * X + 2] = a;
    vc[3 * X] = C4; vc[3 * X + 1] = C1; vc[3 * X + 2] = C3;
    vn[3 * Y] = X; vn[3 * Y + 1] = b; vn[3 * Y + 2] = c;
    vc[3 * Y] = C3; vc[3 * Y + 1] = C2; vc[3 * Y + 2] = C4;
    replace_neighbor(vn, a, u, X);
    replace_neighbor(vn, c, v, Y);
    int n;
    n = sides[C1]; remove_from_row(cell_vertices + (long)C1 * max_sides, &n, Y); sides[C1] = n;
    n = sides[C2]; remove_from_row(cell_vertices + (long)C2 * max_sides, &n, X); sides[C2] = n;
    n = sides[C3]; split_in_row(cell_vertices + (long)C3 * max_sides, &n, u, Y, X); sides[C3] = n;
    n = sides[C4]; split_in_row(cell_vertices + (long)C4 * max_sides, &n, v, X, Y); sides[C4] = n;
    // geometry: the edge turned by 90 degrees about the normal at its midpoint (Surface::t1_positions),
    // the places t1_detect checked
    double full = new_length[r] > 0.0 ? new_length[r] : length_factor * cand_len[i];
    vec3 px, py;
    Surface::t1_positions(pos, u, v, a, b, c, d, Surface::size(size, r), full, &px, &py, e[12] != 0);
    store3(pos, X, px);
    store3(pos, Y, py);
    atomicAdd(flips + r, 1);
    atomicAdd(total_flips + r, 1ull);
    moved[2 * i] = u;              // for Integrator.reset_vertices
    moved[2 * i + 1] = v;
    if (!logging) return;          // no flip-back bookkeeping (T1.counting)
    int slot = atomicAdd(log_count, 1);
    int* entry = log + (long)slot * LOG_INTS;
    // the pass, counted since the log was last replayed (t1_detect)
    entry[0] = *log_pass; entry[1] = C1; entry[2] = C2; entry[3] = C3; entry[4] = C4; entry[5] = r;
}
