/* tests/cuda_host/kernels.cpp -- the force kernels of spherevm (vertex_model.cu, bending.cu, and
 * through them vertex_model.cuh and geometry/sphere.cuh), unmodified, compiled with a host C++
 * compiler: tests/test_cuda_kernels_host.py calls each kernel once per thread through ctypes and
 * compares with the NumPy path. Built with -Itests/cuda_host/kernels first, so that the kernels'
 * "device_common.cuh" is the host stand-in there (thread index, plain per-replica sum).
 */
#include "cuda_host.h"
#include "device_common.cuh"
#include "constraints/sphere.cuh"   // the sphere's device code first, as surface_kernels compiles it
#define SVM_SURFACE SphereSurface
#include "plugins/forces/vertex_model.cu"
#include "plugins/forces/bending.cu"

extern "C" void h_set_thread(long i)
{
    blockIdx.x = (unsigned int)i;
    threadIdx.x = 0;
    blockDim.x = 1;
}
