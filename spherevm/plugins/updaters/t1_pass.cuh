// One T1 pass's three steps for one vertex or one candidate: the bodies of t1.cu's kernels and of
// the fused small-tissue steps (spherevm/tissue_steps.cu), so both flip the same edges to the same
// places. What differs between the two is only where the pass's counters live (global memory for
// the whole State, or shared memory for one tissue), so the callers count.
// Compiled once per surface (geometry/surface.cuh). pos and claim may be a tissue's copies in shared
// memory, offset so that they are indexed by global vertex and cell indices.
#pragma once
#include "geometry/surface.cuh"
#include "plugins/updaters/t1_fold.cuh"

#define CAND_INTS 13   // u, k, v, a, b, c, d, C1, C2, C3, C4, replica, turn
#define LOG_INTS 6     // a flip in the flip log: pass, C1, C2, C3, C4, replica

// Vertex u of replica r: list its edges to higher-numbered neighbours shorter than the chord
// threshold (chord2, squared), and with `untangle` those turned past zero length (t1_bow_tie,
// T1(untangle=True)). *count is the pass's candidate count (a slot each, atomically); slots from
// capacity on are counted but not written.
__device__ __forceinline__ void t1_detect_vertex(const double* pos, const int* vn, const int* vc, Surface::Size s,
                                                 double chord2, bool untangle, int r, int u, int* count, int* cand,
                                                 double* cand_len, int capacity)
{
    vec3 pu = load3(pos, u);
    for (int k = 0; k < 3; ++k) {
        int v = vn[3 * u + k];
        if (v <= u) continue;
        vec3 pv = load3(pos, v);
        bool short_edge = Surface::chord2(pu, pv, s) < chord2;   // chord test: no trigonometry for the many long edges
        if (!short_edge && !untangle) continue;
        int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        int j = vn[3 * v] == u ? 0 : (vn[3 * v + 1] == u ? 1 : 2);
        int a = vn[3 * u + k1], b = vn[3 * u + k2], c = vn[3 * v + (j + 1) % 3], d = vn[3 * v + (j + 2) % 3];
        if (!short_edge && !t1_bow_tie(pos, pu, pv, a, b, c, d, s)) continue;
        int i = atomicAdd(count, 1);
        if (i >= capacity) continue;
        int* e = cand + (long)i * CAND_INTS;
        e[0] = u; e[1] = k; e[2] = v; e[3] = a; e[4] = b; e[5] = c; e[6] = d;
        e[7] = vc[3 * u + k]; e[8] = vc[3 * u + k2]; e[9] = vc[3 * u + k1]; e[10] = vc[3 * v + (j + 1) % 3];
        e[11] = r; e[12] = 0;
        cand_len[i] = Surface::edge_length(pu, pv, s);
    }
}

// The new edge's full length: new_length (> 0: absolute) or length_factor times the old length.
__device__ __forceinline__ double t1_full_length(double new_length, double length_factor, double old_length)
{
    return new_length > 0.0 ? new_length : length_factor * old_length;
}

// Candidate e's topology rules of T1.select: refused if it would leave a triangle with two sides or
// join a cell to itself.
__device__ __forceinline__ bool t1_refused_by_topology(const int* sides, const int* e)
{
    int C1 = e[7], C2 = e[8], C3 = e[9], C4 = e[10];
    bool distinct = C1 != C2 && C1 != C3 && C1 != C4 && C2 != C3 && C2 != C4 && C3 != C4;
    return sides[C1] <= 3 || sides[C2] <= 3 || !distinct;
}

// A kept candidate e: its turn in e[12], and its claims on its four cells (atomicMin: the lowest edge
// index wins).
__device__ __forceinline__ void t1_claim(int* claim, int* e, bool turn)
{
    e[12] = turn ? 1 : 0;
    int index = 3 * e[0] + e[1];
    atomicMin(claim + e[7], index);
    atomicMin(claim + e[8], index);
    atomicMin(claim + e[9], index);
    atomicMin(claim + e[10], index);
}

// folding.t1_placement from the fold levels of the usual and the turned placement: whether the
// candidate is refused, and whether it turns (usual if clean, else turned if clean, else usual
// unless it folds, else, with `untangle` (T1(untangle=True)), turned unless it folds).
__device__ __forceinline__ bool t1_placement_refused(int usual, int turned, bool untangle, bool* turn)
{
    *turn = usual != T1_CLEAN && (turned == T1_CLEAN || (untangle && usual == T1_FOLDS && turned == T1_INVERTED));
    return usual == T1_FOLDS && !*turn;
}

// Candidate e (full: its new length): the rules of T1.select (t1_check, one thread a candidate).
// Refuse a flip by its topology (t1_refused_by_topology), place it as folding.t1_placement does
// (t1_placement_refused; refused if both fold); false if refused. Otherwise it claims its four
// cells (t1_claim).
__device__ __forceinline__ bool t1_check_candidate(const double* pos, const int* vn, const int* sides,
                                                   const int* cell_vertices, int max_sides, Surface::Size s,
                                                   double full, bool untangle, int* claim, int* e)
{
    int u = e[0], v = e[2], a = e[3], b = e[4], c = e[5], d = e[6];
    int C1 = e[7], C2 = e[8], C3 = e[9], C4 = e[10];
    if (t1_refused_by_topology(sides, e)) return false;   // a refused candidate claims nothing
    vec3 px, py;
    Surface::t1_positions(pos, u, v, a, b, c, d, s, full, &px, &py);
    int usual = t1_fold_level(pos, vn, cell_vertices, sides, max_sides, u, v, a, b, c, d, C1, C2, C3, C4, px, py, s);
    int turned = T1_CLEAN;
    if (usual != T1_CLEAN) {
        Surface::t1_positions(pos, u, v, a, b, c, d, s, full, &px, &py, true);
        turned = t1_fold_level(pos, vn, cell_vertices, sides, max_sides, u, v, a, b, c, d, C1, C2, C3, C4, px, py, s);
    }
    bool turn;
    if (t1_placement_refused(usual, turned, untangle, &turn)) return false;
    t1_claim(claim, e, turn);
    return true;
}

// t1_check_candidate by a whole warp (the fused steps: a candidate's check is one thread's long
// chain, which a tissue's few candidates make the pass's critical path): lanes 0-9 take the usual
// placement's fold parts (t1_fold_part), lanes 16-25 the turned placement's, both at once; the
// verdicts (t1_fold_verdict) come from the same values, so the decisions are t1_check's. Every lane
// calls it with the same e and gets the same answer; lane 0 claims.
__device__ __forceinline__ bool t1_check_candidate_warp(const double* pos, const int* vn, const int* sides,
                                                        const int* cell_vertices, int max_sides, Surface::Size s,
                                                        double full, bool untangle, int* claim, int* e)
{
    if (t1_refused_by_topology(sides, e)) return false;
    const unsigned all = 0xffffffffu;
    int lane = threadIdx.x & 31, k = lane & 15;
    T1FoldPart part = {0.0, 0.0, false, false};
    if (k < T1_FOLD_PARTS) {
        vec3 px, py;
        Surface::t1_positions(pos, e[0], e[2], e[3], e[4], e[5], e[6], s, full, &px, &py, lane >= 16);
        part = t1_fold_part(pos, vn, cell_vertices, sides, max_sides, e[0], e[2], e[3], e[4], e[5], e[6], e[7], e[8],
                            e[9], e[10], px, py, s, k);
    }
    bool corner = k >= 4 && k < T1_FOLD_PARTS;
    unsigned new_inverted = __ballot_sync(all, corner && part.inverted_after && !part.inverted_now);
    unsigned inverted = __ballot_sync(all, corner && part.inverted_after);
    int level[2];
    for (int h = 0; h < 2; ++h) {   // the usual placement (lanes 0-15), the turned one (16-31)
        double n[4], after[4];
        for (int j = 0; j < 4; ++j) {
            n[j] = __shfl_sync(all, part.now, 16 * h + j);
            after[j] = __shfl_sync(all, part.after, 16 * h + j);
        }
        level[h] = t1_fold_verdict(n, after, (new_inverted >> (16 * h)) & 0xffffu, (inverted >> (16 * h)) & 0xffffu, s);
    }
    bool turn;
    if (t1_placement_refused(level[0], level[1], untangle, &turn)) return false;
    if (lane == 0) t1_claim(claim, e, turn);
    return true;
}

__device__ __forceinline__ void replace_neighbor(int* vn, int w, int old_v, int new_v) {
    for (int s = 0; s < 3; ++s)
        if (vn[3 * w + s] == old_v) { vn[3 * w + s] = new_v; return; }
}

__device__ __forceinline__ void remove_from_row(int* row, int* n, int x) {
    int p = 0;
    while (row[p] != x) ++p;
    for (int j = p; j < *n - 1; ++j) row[j] = row[j + 1];
    row[*n - 1] = -1;
    *n -= 1;
}

__device__ __forceinline__ void split_in_row(int* row, int* n, int x, int first, int second) {
    int p = 0;
    while (row[p] != x) ++p;
    for (int j = *n; j > p + 1; --j) row[j] = row[j - 1];
    row[p] = first;
    row[p + 1] = second;
    *n += 1;
}

// Candidate e (full: its new length), after every candidate's claims: flip it if it holds all four
// of its cells (true), and give back the cells it holds (claims stay at INT_MAX between passes, so a
// pass costs no sweep over all cells): a cell is held by one candidate, whose thread alone resets it
// after reading it, so no other thread's decision can change. Winners touch disjoint cells and
// vertices, so they need no locks.
__device__ __forceinline__ bool t1_apply_candidate(double* pos, int* vn, int* vc, int* cell_vertices, int* sides,
                                                   int max_sides, Surface::Size s, double full, int* claim,
                                                   const int* e)
{
    int u = e[0], k = e[1], v = e[2], a = e[3], b = e[4], c = e[5], d = e[6];
    int C1 = e[7], C2 = e[8], C3 = e[9], C4 = e[10];
    int index = 3 * u + k, cells[4] = {C1, C2, C3, C4};
    bool mine[4], won = true;
    for (int j = 0; j < 4; ++j) { mine[j] = claim[cells[j]] == index; won = won && mine[j]; }
    for (int j = 0; j < 4; ++j) if (mine[j]) claim[cells[j]] = 0x7fffffff;
    if (!won) return false;
    if (sides[C3] >= max_sides || sides[C4] >= max_sides) return false;   // cannot happen: the table was widened
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
    // the places t1_check checked
    vec3 px, py;
    Surface::t1_positions(pos, u, v, a, b, c, d, s, full, &px, &py, e[12] != 0);
    store3(pos, X, px);
    store3(pos, Y, py);
    return true;
}

// A flip into the flip log (T1.counting): its pass (counted since the log was last replayed), its
// four cells and replica, in the next slot.
__device__ __forceinline__ void t1_log_flip(int* log_count, int* log, int pass, const int* e)
{
    int* entry = log + (long)atomicAdd(log_count, 1) * LOG_INTS;
    entry[0] = pass; entry[1] = e[7]; entry[2] = e[8]; entry[3] = e[9]; entry[4] = e[10]; entry[5] = e[11];
}
