// The Gaussian bump's F and grad F (GaussianBump, bump.py; wrapped by implicit_device.py):
// p = (Lx, Ly, height, width), the Gaussian summed over the images -1, 0, 1 of the minimum-image
// offset from the box's centre.
__device__ inline void images(double d, double L, double w, double* g, double* dg) {
    *g = 0.0;
    *dg = 0.0;
    for (int m = -1; m <= 1; ++m) {
        double s = d - m * L;
        double e = exp(-s * s / (2.0 * w * w));
        *g += e;
        *dg -= s / (w * w) * e;
    }
}
__device__ inline void height(vec3 x, const double* p, double* z, double* zx, double* zy) {
    double dx = x.x - 0.5 * p[0], dy = x.y - 0.5 * p[1];
    dx -= p[0] * rint(dx / p[0]);
    dy -= p[1] * rint(dy / p[1]);
    double gx, dgx, gy, dgy;
    images(dx, p[0], p[3], &gx, &dgx);
    images(dy, p[1], p[3], &gy, &dgy);
    *z = p[2] * gx * gy;
    *zx = p[2] * dgx * gy;
    *zy = p[2] * gx * dgy;
}
__device__ inline double F(vec3 x, const double* p) {
    double z, zx, zy;
    height(x, p, &z, &zx, &zy);
    return x.z - z;
}
__device__ inline vec3 grad_F(vec3 x, const double* p) {
    double z, zx, zy;
    height(x, p, &z, &zx, &zy);
    return v3(-zx, -zy, 1.0);
}
