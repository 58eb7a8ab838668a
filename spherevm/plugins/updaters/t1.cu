// T1 neighbour exchanges on the device: the CUDA path of t1.py, same rules and same geometry.
// A pass is three kernels: t1_detect (one thread per vertex, its edges to higher-numbered
// neighbours) lists the short edges (with `untangle` also those turned past zero length,
// t1_fold.cuh's t1_bow_tie); t1_check (one thread per listed edge) applies the refusal
// rules and lets each remaining candidate claim its four cells (lowest edge index wins); after one
// small read-back of the counters, t1_apply (one thread per candidate) flips the winners and gives
// back the cells each candidate holds. Their bodies are t1_pass.cuh's (shared with the fused
// small-tissue steps, spherevm/tissue_steps.cu).
// The checks are a kernel of their own because they are long (t1_fold.cuh): inside t1_detect their
// registers slowed the short-edge test of every vertex (356 us of a 1e6-cell step on an H200).
// Compiled once per surface (geometry/surface.cuh): the short-edge test and the new positions are
// the surface's. A candidate whose flip would fold the network (t1_fold.cuh) turns the other way
// if that does not fold it, and is refused otherwise (folding.t1_placement).
#include "plugins/updaters/t1_pass.cuh"

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
    const bool* __restrict__ active, int untangle, int n_vertices, int* __restrict__ counters,
    int* __restrict__ cand, double* __restrict__ cand_len, int capacity, int* __restrict__ log_pass)
{
    int u = blockIdx.x * blockDim.x + threadIdx.x;
    if (u == 0) *log_pass += 1;
    if (u >= n_vertices) return;
    int r = vertex_replica[u];
    if (!active[r]) return;
    t1_detect_vertex(pos, vn, vc, Surface::size(size, r), chord2[r], untangle != 0, r, u, counters, cand, cand_len,
                     capacity);
}

// One thread per slot (n_slots: the room; the candidate count is read here, counters[0]):
// t1_check_candidate, counting the refused and the claimants.
// new_length[r] > 0: absolute new length per replica; else length_factor times the old length.
extern "C" __global__ void t1_check(
    const double* __restrict__ pos, const int* __restrict__ vn, const int* __restrict__ sides,
    const int* __restrict__ cell_vertices, const double* __restrict__ size, const double* __restrict__ new_length,
    double length_factor, int max_sides, int* __restrict__ claim, int* __restrict__ refused,
    unsigned long long* __restrict__ total_refused, int* __restrict__ counters, int* __restrict__ cand,
    const double* __restrict__ cand_len, int n_slots, const int* __restrict__ width, int untangle)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n_slots || i >= counters[0]) return;
    int* e = cand + (long)i * CAND_INTS;
    int r = e[11];
    double full = t1_full_length(new_length[r], length_factor, cand_len[i]);
    if (!t1_check_candidate(pos, vn, sides, cell_vertices, max_sides, Surface::size(size, r), full, untangle != 0,
                            claim, e)) {
        atomicAdd(refused + r, 1);
        atomicAdd(total_refused + r, 1ull);
        return;
    }
    atomicAdd(counters + 2, 1);
    if (sides[e[9]] >= *width || sides[e[10]] >= *width) counters[1] = 1;
}

// One thread per slot of `moved` (n_slots: the candidate count after the read-back, or the whole
// capacity inside a CUDA graph, where the count is read here: counters[0]): t1_apply_candidate,
// counting the flips, listing the moved vertices and, with `logging`, the flip log. grow_width:
// inside a graph the width the host widens step by step grows here.
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
    int r = e[11];
    double full = t1_full_length(new_length[r], length_factor, cand_len[i]);
    if (!t1_apply_candidate(pos, vn, vc, cell_vertices, sides, max_sides, Surface::size(size, r), full, claim, e))
        return;
    atomicAdd(flips + r, 1);
    atomicAdd(total_flips + r, 1ull);
    moved[2 * i] = e[0];           // for Integrator.reset_vertices
    moved[2 * i + 1] = e[2];
    if (logging) t1_log_flip(log_count, log, *log_pass, e);   // the pass: t1_detect's count
}
