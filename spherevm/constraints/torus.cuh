// The torus's F, grad F and closed-form closest point (Torus, torus.py; wrapped by
// implicit_device.py): p = (R, r), c = R (x, y, 0) / rho the nearest point of the core circle.
__device__ inline vec3 core(vec3 x, const double* p) {
    double rho = sqrt(x.x * x.x + x.y * x.y);
    return v3(p[0] * x.x / rho, p[0] * x.y / rho, 0.0);
}
__device__ inline double F(vec3 x, const double* p) {
    double rho = sqrt(x.x * x.x + x.y * x.y);
    return (rho - p[0]) * (rho - p[0]) + x.z * x.z - p[1] * p[1];
}
__device__ inline vec3 grad_F(vec3 x, const double* p) { return 2.0 * (x - core(x, p)); }
__device__ inline vec3 project(vec3 x, const double* p) {
    vec3 c = core(x, p), d = x - c;
    return c + (p[1] / sqrt(dot3(d, d))) * d;
}
