"""spherevm.ovito against the real ovito package: one face (and region) per cell, the properties,
the replicas side by side."""
import numpy as np
import pytest

import spherevm as svm

pytest.importorskip("ovito")


def test_pipeline_cell_mesh(tmp_path):
    import spherevm.ovito as so
    path = tmp_path / "run.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(24, replicas=2, seed=5)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    sim.operations.writers.append(svm.plugins.writers.GSD(20, str(path)))
    sim.run(40)
    sim.operations.writers[0].close()
    pipeline = so.pipeline(path, side_by_side=False)
    for frame in (0, 2):
        data = pipeline.compute(frame)
        mesh = data.surfaces["cells"]
        state = svm.init.from_gsd(path, frame)
        stored = svm.gsdio.read_cell_values(path, frame)
        assert mesh.faces.count == state.n_cells and mesh.regions.count == state.n_cells
        assert np.array_equal(mesh.faces["Region"], np.arange(state.n_cells))
        assert np.array_equal(mesh.faces["replica"], state.cell_replica_np())
        for q in ("shape_index", "area", "perimeter", "energy"):
            assert np.allclose(mesh.faces[q], stored[q], equal_nan=True)
        # curved edges: SEGMENTS points per side, on the sphere
        assert mesh.vertices.count == so.SEGMENTS * state.cell_sides.sum()
        r = np.linalg.norm(np.asarray(mesh.vertices["Position"]), axis=1)
        assert np.allclose(np.sort(np.unique(np.round(r, 9))), np.unique(np.round(state.radius_np(), 9)))
        assert mesh.vis.color_mapping_property == "shape_index"
        assert data.particles.bonds.vis.width == pytest.approx(so.BOND_WIDTH)


def _write(path, state, steps=0):
    sim = svm.Simulation(device="cpu")
    sim.state = state
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    sim.operations.writers.append(svm.plugins.writers.GSD(10, str(path)))
    sim.run(steps)
    sim.operations.writers[0].close()
    return svm.init.from_gsd(path)


@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_replicas_side_by_side_and_cells_on_their_vertices(tmp_path, surface):
    """By default each replica's particles and cells move by export.replica_offsets (replica 0 stays);
    every cell's first corner is its first vertex's particle (on the plane too, whose particles the
    file centres on the origin); side_by_side=False leaves the file's positions."""
    import spherevm.ovito as so
    from spherevm.export import replica_offsets
    path = tmp_path / "run.gsd"
    make = svm.init.random_tiling if surface == "sphere" else svm.init_plane.random_planar_tiling
    state = _write(path, make(20, replicas=3, seed=4))
    shift = replica_offsets(state)
    assert shift[0].tolist() == [0, 0, 0] and (np.diff(shift[:, 0]) > 0).all()
    overlapping = so.pipeline(path, side_by_side=False).compute(0)
    apart = so.pipeline(path).compute(0)
    vrep, crep = state.vertex_replica_np(), state.cell_replica_np()
    p0, p1 = np.asarray(overlapping.particles.positions), np.asarray(apart.particles.positions)
    np.testing.assert_allclose(p1 - p0, shift[vrep], atol=1e-5)
    starts = np.concatenate([[0], np.cumsum(so.SEGMENTS * state.cell_sides)[:-1]])
    for data in (overlapping, apart):
        corners = np.asarray(data.surfaces["cells"].vertices["Position"])[starts]
        np.testing.assert_allclose(corners, np.asarray(data.particles.positions)[state.cell_vertices[:, 0]], atol=1e-5)
    # the replicas' cells no longer overlap along x
    mesh = np.asarray(apart.surfaces["cells"].vertices["Position"])
    face_rep = np.repeat(crep, so.SEGMENTS * state.cell_sides)
    spans = [(mesh[face_rep == r, 0].min(), mesh[face_rep == r, 0].max()) for r in range(3)]
    assert all(spans[r][1] < spans[r + 1][0] for r in range(2)), spans


def test_ovito_reads_a_growing_tissue(tmp_path):
    """A GSD file whose particle count changes from frame to frame (divisions and T2s on a sphere
    that grows with N): OVITO's own GSD reader gives each frame's vertices and edges, and the cell
    mesh of spherevm.ovito each frame's cells."""
    import spherevm.ovito as so
    from ovito.io import import_file
    path = tmp_path / "grow.gsd"
    sim = svm.Simulation(device="cpu", seed=5)
    sim.state = svm.init.random_tiling(16, replicas=2, seed=2)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters += [svm.plugins.updaters.T1(), svm.plugins.updaters.Division(rule="rate", rate=0.1, dt=1.0),
                                svm.plugins.updaters.Extrusion(area_threshold=0.4),
                                svm.plugins.updaters.RadiusSchedule("constant_area")]
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.05)
    sim.operations.writers.append(svm.plugins.writers.GSD(trigger=2, filename=str(path)))
    states = [sim.state.copy()]
    for _ in range(6):
        sim.run(2)
        states.append(sim.state.copy())
    sim.operations.writers[0].close()
    assert len({s.n_vertices for s in states}) >= 4              # the count changes along the file
    plain, cells = import_file(str(path)), so.pipeline(path)
    assert plain.source.num_frames == cells.source.num_frames == len(states)
    for frame, state in enumerate(states):
        data = plain.compute(frame)
        assert data.attributes["Timestep"] == 2 * frame
        assert data.particles.count == state.n_vertices
        np.testing.assert_array_equal(data.particles["replica"], state.vertex_replica_np())
        np.testing.assert_array_equal(data.particles.positions, state.positions.astype(np.float32))
        bonds = np.sort(np.asarray(data.particles.bonds.topology), axis=1)
        expected = svm.topology.edges(state.vertex_neighbors)
        assert data.particles.bonds.count == 3 * state.n_vertices // 2
        np.testing.assert_array_equal(bonds, expected)
        mesh = cells.compute(frame).surfaces["cells"]
        assert mesh.faces.count == state.n_cells and mesh.regions.count == state.n_cells
        assert np.array_equal(mesh.faces["replica"], state.cell_replica_np())
        assert mesh.vertices.count == so.SEGMENTS * state.cell_sides.sum()
