// tests/cuda_host/t1_fold_harness_plane.cpp -- t1_fold_harness.cpp for the periodic plane (the T1
// kernels compiled with -DSVM_SURFACE_PLANE, as spherevm.constraints.kernels.surface_kernels does).
#define SVM_SURFACE_PLANE
#include "t1_fold_harness.cpp"
