// The surface a kernel is compiled for: one kernel source serves every surface. Each surface is a
// struct of static device functions with the same names, which its constraint supplies as device
// code (Constraint.device_surface: SphereSurface in constraints/sphere.cuh, PlaneSurface in
// constraints/plane.cuh, ImplicitSurface<Shape> in constraints/implicit.cuh). The module's source
// starts with that code and names the struct SVM_SURFACE (spherevm.constraints.kernels.surface_kernels);
// a kernel calls it through `Surface`.
//
//   Size                      the per-replica size (a radius, a box (Lx, Ly), an implicit surface's
//                             parameters)
//   size(s, r)                replica r's size from the size array the kernels take
//                             (DeviceSurface.size_array)
//   vertex_size               whether the vertex-force kernel needs each vertex's size
//   directions                whether the vertex model's functions use the vertices' unit directions
//                             x / |x| (the sphere), through a Norm: 1 / |x| of vertex i, computed
//                             (RsqrtNorm, the default) or kept from before (KeptNorm)
//   cell_measures(...)        a cell's area and perimeter
//   area_unit, length_unit    what the vertex-force coefficients are scaled by
//   coef_width                the vertex model's doubles per cell: 2 (a_c, p_c), or 4 on implicit
//                             surfaces (facet: the vector area a_c, coefficients (a_c a / A, p_c))
//   periodic, period(s)       whether edges are minimum images in the box period(s)
//   vertex_force(...)         minus the surface gradient of sum_c a_c A_c + p_c P_c at a vertex (on the
//                             sphere a force fused into the vertex model adds its gradient through
//                             an `extra`, see plugins/forces/vertex_model.cuh)
//   normal(x, s)              the unit normal at x
//   place(y, n, s)            P_N: the surface point for y, whose normal n = normal(y) the caller has
//   placed_normal(x, n, s)    the unit normal at x = place(y, n, s): n itself where P_N moves along
//                             the normal line of y (the sphere, the plane), normal(x, s) otherwise
//   cell_normal(..., s)       the normal at a cell's centre (active cell directors)
//   chord2, edge_length       the T1 short-edge test and the edge's length
//   t1_positions(...)         the two vertices of a flipped edge
//   triangle_area(a, b, c, s) the sign-carrying area of a triangle, half_area(s) half the surface's
//                             in the same unit, delta(a, b, s) the vector a -> b (T1's fold rule,
//                             plugins/updaters/t1_fold.cuh)
//   crossing_point(p, ref, s) p as a 3-vector whose triple products give orientations, the image
//                             nearest ref on the plane (simplicity.points; T1's untangling)
#pragma once

#include "geometry/surface_parts.cuh"

#ifndef SVM_SURFACE
#error "no surface: start the source with a constraint's device code (spherevm.constraints.kernels.surface_kernels)"
#endif
typedef SVM_SURFACE Surface;
