"""spherevm.ovito against the real ovito package: one face (and region) per cell, the properties."""
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
    pipeline = so.pipeline(path)
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
