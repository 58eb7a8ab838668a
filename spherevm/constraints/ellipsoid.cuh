// The ellipsoid's F and grad F (Ellipsoid, ellipsoid.py; wrapped by implicit_device.py): p = (a, b, c).
__device__ inline double F(vec3 x, const double* p) {
    return (x.x / p[0]) * (x.x / p[0]) + (x.y / p[1]) * (x.y / p[1]) + (x.z / p[2]) * (x.z / p[2]) - 1.0;
}
__device__ inline vec3 grad_F(vec3 x, const double* p) {
    return v3(2.0 * x.x / (p[0] * p[0]), 2.0 * x.y / (p[1] * p[1]), 2.0 * x.z / (p[2] * p[2]));
}
