// tests/cuda_host/t1_fold_harness_plane.cpp -- t1_fold_harness.cpp for the periodic plane (the T1
// kernels compiled after the plane's device code, as spherevm.constraints.kernels.surface_kernels does).
#include "cuda_host.h"
#include "constraints/plane.cuh"
#define SVM_SURFACE PlaneSurface
#include "t1_fold_harness.cpp"
