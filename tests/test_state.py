"""State construction, validation and the errors bad input gets."""
import numpy as np
import pytest
from conftest import to_numpy

import spherevm as svm


def test_random_tiling_layout_and_euler(device):
    s = svm.init.random_tiling(100, replicas=3, seed=2, device=device)
    assert s.n_replicas == 3 and s.n_cells == 300
    assert s.n_vertices == 3 * (2 * 100 - 4)  # V = 2F - 4 for a trivalent sphere
    nv, nc = s.vertices_per_replica, s.cells_per_replica
    assert np.all(nv - 3 * nv // 2 + nc == 2)
    assert s.positions.dtype == np.float64 and s.cell_vertices.dtype == np.int32
    assert np.allclose(s.radius_np(), np.sqrt(100 / (4 * np.pi)))
    assert np.allclose(s.mean_cell_area, 1.0)
    assert np.allclose(np.linalg.norm(to_numpy(s.positions), axis=1), s.radius_np()[s.vertex_replica_np()],
                       rtol=1e-14)


def test_same_seed_same_tiling_and_replicas_independent_of_count():
    a = svm.init.random_tiling(50, replicas=2, seed=5)
    b = svm.init.random_tiling(50, replicas=4, seed=5)
    assert np.array_equal(a.positions, b.positions[:a.n_vertices])
    assert np.array_equal(a.cell_vertices[:, :a.max_sides].clip(-1), a.cell_vertices)
    c = svm.init.random_tiling(50, replicas=1, seed=6)
    assert not np.array_equal(a.positions[:c.n_vertices], c.positions)


def test_replica_extraction_roundtrip(device):
    s = svm.init.random_tiling(40, replicas=3, seed=1, device=device)
    parts = [s.replica(r) for r in range(3)]
    back = svm.State.concatenate(parts)
    assert back.device.name == s.device.name
    for name in ("positions", "vertex_neighbors", "vertex_cells"):
        assert np.array_equal(to_numpy(getattr(back, name)), to_numpy(getattr(s, name))), name
    back.validate()


def test_vertex_tables_follow_the_orientation_convention():
    s = svm.init.random_tiling(30, seed=4)
    cv, vn, vc = s.cell_vertices, s.vertex_neighbors, s.vertex_cells
    for v in range(s.n_vertices):
        for k in range(3):
            row = cv[vc[v, k], :s.cell_sides[vc[v, k]]].tolist()
            i = row.index(v)
            assert row[(i + 1) % len(row)] == vn[v, k]
            assert row[i - 1] == vn[v, (k + 1) % 3]


def _dodeca_polygons():
    s = svm.init.regular_tiling("dodecahedron")
    cells = [row[:n].tolist() for row, n in zip(s.cell_vertices, s.cell_sides)]
    return s.positions.copy(), cells, float(s.radius_np()[0])


def test_from_polygons_rejects_a_clockwise_cell():
    pos, cells, R = _dodeca_polygons()
    cells[3] = cells[3][::-1]
    with pytest.raises(ValueError, match="clockwise|fan"):
        svm.init.from_polygons(pos, cells, R)


def test_from_polygons_rejects_all_cells_clockwise():
    pos, cells, R = _dodeca_polygons()
    with pytest.raises(ValueError, match="cell 0 .*clockwise"):
        svm.init.from_polygons(pos, [c[::-1] for c in cells], R)


def test_from_polygons_rejects_non_trivalent():
    pos, cells, R = _dodeca_polygons()
    cells = cells + [[cells[0][0], cells[0][1], cells[1][0]]]
    with pytest.raises(ValueError, match="not trivalent: vertex"):
        svm.init.from_polygons(pos, cells, R)


@pytest.mark.parametrize("bad, match", [
    (dict(n_cells=3), "n_cells must be an integer >= 4"),
    (dict(n_cells=10.5), "n_cells"),
    (dict(n_cells=10, replicas=0), "replicas must be"),
    (dict(n_cells=10, radius=-1.0), "radius must be positive"),
    (dict(n_cells=10, radius=0.0), "radius must be positive"),
    (dict(n_cells=10, radius=float("nan")), "radius must be positive"),
    (dict(n_cells=10, seed=-1), "seed must be"),
    (dict(n_cells=10, device="tpu"), "device must be one of"),
])
def test_random_tiling_bad_input(bad, match):
    with pytest.raises(ValueError, match=match):
        svm.init.random_tiling(**bad)


def test_validate_names_nan_vertex(device):
    s = svm.init.random_tiling(20, seed=0, device=device)
    s.positions[7] = np.nan
    with pytest.raises(ValueError, match="vertex 7"):
        s.validate()


def test_validate_names_vertex_off_surface(device):
    s = svm.init.random_tiling(20, seed=0, device=device)
    s.positions[5] *= 1.01
    with pytest.raises(ValueError, match="vertex 5 is off the surface"):
        s.validate()


def test_validate_catches_broken_reciprocity(device):
    s = svm.init.random_tiling(20, seed=0, device=device)
    s.vertex_neighbors[4, 0] = s.vertex_neighbors[4, 1]
    with pytest.raises(ValueError, match="vertex 4"):
        s.validate()


def test_regular_tiling_unknown_name():
    with pytest.raises(ValueError, match="name must be one of"):
        svm.init.regular_tiling("cube")


def test_unknown_device_in_simulation():
    with pytest.raises(ValueError, match="device must be one of"):
        svm.Simulation(device="cuda:7")
