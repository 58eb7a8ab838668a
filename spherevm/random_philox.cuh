/* spherevm/random_philox.cuh -- counter-based random numbers for spherevm CUDA kernels.
 *
 * The CUDA twin of spherevm/random.py (see docs/random.md). Same construction, same formulas:
 *
 *   key     = (seed, stream)                                      two uint32 words
 *   counter = (id, timestep & 0xffffffff, timestep >> 32, block)  four uint32 words
 *   words   = Philox4x32-10(counter, key) = (w0, w1, w2, w3)
 *
 * Draw j (0-based) of an id comes from block j / 2: the pair (w0, w1) when j is even, (w2, w3)
 * when j is odd.
 *
 *   uniform from a pair (hi, lo):  n = (hi << 20) | (lo >> 12)            (52-bit integer)
 *                                  u = (double)(2 n + 1) * 2^-53           (exact; in (0, 1))
 *   normal pair from block b:      u1 = uniform(w0, w1), u2 = uniform(w2, w3)
 *                                  r = sqrt(-2 log u1), t = SVM_TWO_PI * u2
 *                                  z[2b] = r cos t,  z[2b + 1] = r sin t
 *
 * Guarantees: Philox words and uniforms are bitwise identical to the NumPy path (integer
 * arithmetic, an exact int->double conversion and an exact power-of-two scale). Normals go
 * through log/sqrt/sin/cos, whose CUDA and host libm versions may differ by an ulp or two, so
 * they agree to ~1e-16 relative, not necessarily bitwise. No expression here is of the form
 * a * b + c, so FMA contraction cannot change results.
 *
 * Usable from nvcc (host and device) and from NVRTC / CuPy RawKernel (no includes needed there).
 * Everything is prefixed svm_ so that the header can sit beside Random123 or cuRAND.
 */
#ifndef SPHEREVM_RANDOM_PHILOX_CUH
#define SPHEREVM_RANDOM_PHILOX_CUH

#if !defined(__CUDACC_RTC__)
#include <math.h>
#endif

#if defined(__CUDACC__)
#define SVM_RNG_FN __host__ __device__ __forceinline__
#else
#define SVM_RNG_FN static inline
#endif

/* Stream numbers: keep in sync with STREAM_* in spherevm/random.py. */
#define SVM_STREAM_BROWNIAN 0u /* integrator translational noise, indexed by vertex id */
#define SVM_STREAM_ACTIVE 1u   /* cell director (polarity) rotational noise, indexed by cell id */
#define SVM_STREAM_DIRECTOR_INIT 2u /* initial director angles (timestep 0), indexed by cell id */
#define SVM_STREAM_DIVISION 3u /* cell division (draw 0: whether, 1: cut angle, 2: daughter's director), by cell id */
#define SVM_STREAM_VERTEX_BIRTH 4u /* director of a vertex a division creates, indexed by vertex id */

/* Philox4x32 constants (Salmon et al., SC'11; Random123 philox.h). */
#define SVM_PHILOX_M0 0xD2511F53u
#define SVM_PHILOX_M1 0xCD9E8D57u
#define SVM_PHILOX_W0 0x9E3779B9u
#define SVM_PHILOX_W1 0xBB67AE85u

#define SVM_TWO_PI 6.283185307179586             /* the double nearest 2 pi */
#define SVM_TWO_M53 (1.0 / 9007199254740992.0)   /* 2^-53, exact */

/* High 32 bits of the 64-bit product a * b (the low 32 bits are just a * b in 32-bit). */
SVM_RNG_FN unsigned int svm_mulhi32(unsigned int a, unsigned int b)
{
#if defined(__CUDA_ARCH__)
    return __umulhi(a, b);
#else
    return (unsigned int)(((unsigned long long)a * (unsigned long long)b) >> 32);
#endif
}

/* One Philox4x32 round: (c0, c1, c2, c3) -> (hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0). */
SVM_RNG_FN uint4 svm_philox4x32_round(uint4 c, uint2 k)
{
    const unsigned int hi0 = svm_mulhi32(SVM_PHILOX_M0, c.x);
    const unsigned int lo0 = SVM_PHILOX_M0 * c.x;
    const unsigned int hi1 = svm_mulhi32(SVM_PHILOX_M1, c.z);
    const unsigned int lo1 = SVM_PHILOX_M1 * c.z;
    return make_uint4(hi1 ^ c.y ^ k.x, lo1, hi0 ^ c.w ^ k.y, lo0);
}

/* Philox4x32 with R rounds; the key is bumped (mod 2^32) before every round but the first. */
SVM_RNG_FN uint4 svm_philox4x32_R(unsigned int rounds, uint4 c, uint2 k)
{
    for (unsigned int r = 0; r < rounds; ++r) {
        if (r > 0) {
            k.x += SVM_PHILOX_W0;
            k.y += SVM_PHILOX_W1;
        }
        c = svm_philox4x32_round(c, k);
    }
    return c;
}

/* Philox4x32-10: the block function used for every spherevm draw. */
SVM_RNG_FN uint4 svm_philox4x32_10(uint4 c, uint2 k)
{
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
    for (unsigned int r = 0; r < 10u; ++r) {
        if (r > 0) {
            k.x += SVM_PHILOX_W0;
            k.y += SVM_PHILOX_W1;
        }
        c = svm_philox4x32_round(c, k);
    }
    return c;
}

/* The Philox words of block `block` for one id: counter (id, t_lo, t_hi, block), key (seed, stream). */
SVM_RNG_FN uint4 svm_rng_block(unsigned int seed, unsigned int stream, unsigned long long timestep,
                               unsigned int id, unsigned int block)
{
    const uint4 c = make_uint4(id, (unsigned int)(timestep & 0xFFFFFFFFull),
                               (unsigned int)(timestep >> 32), block);
    return svm_philox4x32_10(c, make_uint2(seed, stream));
}

/* Two uint32 words -> double in [2^-53, 1 - 2^-53]: (2 ((hi << 20) | (lo >> 12)) + 1) * 2^-53. */
SVM_RNG_FN double svm_u01(unsigned int hi, unsigned int lo)
{
    const unsigned long long n = ((unsigned long long)hi << 20) | (unsigned long long)(lo >> 12);
    return (double)((n << 1) | 1ull) * SVM_TWO_M53;
}

/* Box-Muller on the two uniforms of one block: z0 = r cos t, z1 = r sin t. */
SVM_RNG_FN void svm_box_muller(uint4 w, double *z0, double *z1)
{
    const double u1 = svm_u01(w.x, w.y);
    const double u2 = svm_u01(w.z, w.w);
    const double r = sqrt(-2.0 * log(u1));
    const double t = SVM_TWO_PI * u2;
    *z0 = r * cos(t);
    *z1 = r * sin(t);
}

/* Draws 2b and 2b + 1 of an id at once (one Philox call): uniforms. */
SVM_RNG_FN void svm_uniform2(unsigned int seed, unsigned int stream, unsigned long long timestep,
                             unsigned int id, unsigned int b, double *u0, double *u1)
{
    const uint4 w = svm_rng_block(seed, stream, timestep, id, b);
    *u0 = svm_u01(w.x, w.y);
    *u1 = svm_u01(w.z, w.w);
}

/* Draws 2b and 2b + 1 of an id at once (one Philox call): standard normals. */
SVM_RNG_FN void svm_normal2(unsigned int seed, unsigned int stream, unsigned long long timestep,
                            unsigned int id, unsigned int b, double *z0, double *z1)
{
    svm_box_muller(svm_rng_block(seed, stream, timestep, id, b), z0, z1);
}

/* Draw j of an id: equals spherevm.random.uniform(seed, stream, timestep, [id], count)[0, j]. */
SVM_RNG_FN double svm_uniform(unsigned int seed, unsigned int stream, unsigned long long timestep,
                              unsigned int id, unsigned int j)
{
    const uint4 w = svm_rng_block(seed, stream, timestep, id, j >> 1);
    return (j & 1u) ? svm_u01(w.z, w.w) : svm_u01(w.x, w.y);
}

/* Draw j of an id: equals spherevm.random.normal(seed, stream, timestep, [id], count)[0, j]
 * to ~1 ulp. Prefer svm_normal2 when both draws of a block are needed. */
SVM_RNG_FN double svm_normal(unsigned int seed, unsigned int stream, unsigned long long timestep,
                             unsigned int id, unsigned int j)
{
    double z0, z1;
    svm_normal2(seed, stream, timestep, id, j >> 1, &z0, &z1);
    return (j & 1u) ? z1 : z0;
}

#endif /* SPHEREVM_RANDOM_PHILOX_CUH */
