// The ellipsoid's F and grad F (Ellipsoid, ellipsoid.py; wrapped by implicit_device.py):
// p = (1/a^2, 1/b^2, 1/c^2) (Ellipsoid.device_parameters), so that neither divides.
__device__ inline double F(vec3 x, const double* p) {
    return x.x * x.x * p[0] + x.y * x.y * p[1] + x.z * x.z * p[2] - 1.0;
}
__device__ inline vec3 grad_F(vec3 x, const double* p) {
    return v3(2.0 * x.x * p[0], 2.0 * x.y * p[1], 2.0 * x.z * p[2]);
}
