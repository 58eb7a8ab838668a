"""Tests that kill mutants of spherevm/constraints/plane.py that survived tests/test_plane.py.

Found with ``python3 benchmarks/mutate.py spherevm/constraints/plane.py ...`` (docs/testing.md,
"Mutation testing"): the pointwise maps on a non-square box, edge lengths, the unwrapped polygons
and the cell centres, each against a computation written here.
"""
import numpy as np

import spherevm as svm
from spherevm.constraints import PeriodicPlane

BOX = np.array([4.0, 9.0])


def test_length_scale_area_and_box_test_on_a_non_square_box():
    con = PeriodicPlane()
    assert con.length_scale(np.array([BOX, [1.0, 16.0]])).tolist() == [6.0, 4.0]
    assert con.total_area_np(BOX) == 36.0
    pts = np.array([[1.0, 2.0, 0.0], [-1e-9, 2.0, 0.0], [1.0, 9.0, 0.0], [4.0, 0.0, 0.0], [3.9, 8.9, 0.0]])
    assert con.outside_box(pts, BOX).tolist() == [False, True, True, True, False]


def test_geodesic_offset_is_the_wrapped_straight_step():
    con = PeriodicPlane()
    x = np.array([[3.5, 8.5, 0.0], [0.5, 0.5, 0.0]])
    direction = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    got = con.geodesic_offset(x, direction, np.array([1.0, 2.0]), BOX)
    np.testing.assert_allclose(got, [[0.5, 8.5, 0.0], [0.5, 7.5, 0.0]], rtol=0, atol=1e-15)


def _tiling():
    return svm.State.concatenate([svm.init.random_planar_tiling(20, seed=3, box=(4.0, 9.0)),
                                  svm.init.random_planar_tiling(12, seed=4, box=(5.0, 3.0))])


def _unwrapped_polygon(s, c):
    """Vertex positions of cell c, each neighbour placed at the minimum image of the one before."""
    box = s.box_np()[s.cell_replica_np()[c]]
    verts = s.cell_vertices[c, :s.cell_sides[c]]
    pts = [s.positions[verts[0], :2]]
    for a, b in zip(verts[:-1], verts[1:]):
        d = s.positions[b, :2] - s.positions[a, :2]
        pts.append(pts[-1] + d - box * np.rint(d / box))
    return np.array(pts), box


def test_edge_lengths_are_minimum_image_distances():
    s = _tiling()
    con = s.constraint
    u = np.arange(s.n_vertices)
    v = s.vertex_neighbors[:, 0]
    box = s.box_np()[s.vertex_replica_np()]
    d = s.positions[v, :2] - s.positions[u, :2]
    d -= box * np.rint(d / box)
    np.testing.assert_allclose(con.edge_lengths(s, u, v), np.hypot(d[:, 0], d[:, 1]), rtol=1e-15, atol=0)


def test_unwrapped_cells_and_centres_against_an_independent_unwrapping():
    s = _tiling()
    first, valid, e, r = s.constraint.unwrapped_cells(s)
    centres = s.constraint.cell_centers(s)
    assert centres.shape == (s.n_cells, 3) and np.all(centres[:, 2] == 0)
    for c in range(s.n_cells):
        pts, box = _unwrapped_polygon(s, c)
        n = len(pts)
        np.testing.assert_allclose(r[c, :n], pts - pts[0], rtol=0, atol=1e-12)
        want = np.mod(pts.mean(axis=0), box)
        np.testing.assert_allclose(centres[c, :2], want, rtol=0, atol=1e-12)
    assert np.all(r[:, 0] == 0) and first[:, 0].tolist() == s.cell_vertices[:, 0].tolist()
