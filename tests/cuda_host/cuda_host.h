/* tests/cuda_host/cuda_host.h -- compile spherevm's pure-arithmetic CUDA headers with a host C++
 * compiler, so that the test suite checks them on machines without a GPU (docs/testing.md).
 *
 * Include this before the headers. It supplies only what they take from CUDA: the function
 * qualifiers (empty or plain inline on the host), the vector types uint2/uint4 and their make_*
 * constructors, rsqrt and the rounded intrinsics __fma_rn, __dmul_rn, __dadd_rn, __dsub_rn and
 * __ddiv_rn. Nothing here changes a formula; the headers are included unmodified.
 *
 * rsqrt: CUDA's double rsqrt(x) is 1/sqrt(x) to about 1 ulp (not correctly rounded). The host
 * stand-in 1.0 / sqrt(x) is two correctly rounded operations, also within 1 ulp; the two may differ
 * in the last bit, which is why the geometry is compared with a tolerance and not bitwise.
 */
#ifndef SPHEREVM_TESTS_CUDA_HOST_H
#define SPHEREVM_TESTS_CUDA_HOST_H

#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
#error "cuda_host.h is for host compilers only; nvcc and NVRTC provide the real definitions"
#endif

#include <math.h>

#define __host__
#define __device__
#define __global__
#define __forceinline__ inline
#define __noinline__ __attribute__((noinline))
#define __launch_bounds__(...)
#define __restrict__ __restrict

struct uint2 { unsigned int x, y; };
struct uint4 { unsigned int x, y, z, w; };

static inline uint2 make_uint2(unsigned int x, unsigned int y) { uint2 r = {x, y}; return r; }
static inline uint4 make_uint4(unsigned int x, unsigned int y, unsigned int z, unsigned int w)
{
    uint4 r = {x, y, z, w};
    return r;
}

static inline double rsqrt(double x) { return 1.0 / sqrt(x); }

/* The correctly rounded intrinsics the headers write out where the bits must not depend on the
 * compiler's fusing (FIRE's move, a spherical cell's corner sums): the same operations on the host. */
static inline double __fma_rn(double a, double b, double c) { return fma(a, b, c); }
static inline double __dmul_rn(double a, double b) { return a * b; }
static inline double __dadd_rn(double a, double b) { return a + b; }
static inline double __dsub_rn(double a, double b) { return a - b; }
static inline double __ddiv_rn(double a, double b) { return a / b; }

#endif /* SPHEREVM_TESTS_CUDA_HOST_H */
