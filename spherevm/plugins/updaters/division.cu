// Cell division on the GPU: the rate rule's draws, the same Philox uniforms as spherevm.random
// (bit for bit, random_philox.cuh), so the GPU chooses the cells the CPU chooses.
#include "random_philox.cuh"

// chosen[c] = 1 if draw 0 of cell c (stream SVM_STREAM_DIVISION, counted by (timestep, c)) is < p.
extern "C" __global__ void division_draws(unsigned int seed, unsigned long long timestep, int n_cells, double p,
                                          unsigned char* __restrict__ chosen)
{
    int c = blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    double u0, u1;
    svm_uniform2(seed, SVM_STREAM_DIVISION, timestep, (unsigned int)c, 0u, &u0, &u1);
    chosen[c] = (u0 < p) ? 1 : 0;
}
