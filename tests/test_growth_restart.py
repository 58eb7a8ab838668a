"""Checkpoints of a growing tissue (issue 16, item 3): N steps, a GSD checkpoint, a new Simulation
with freshly built operations and N more steps give the 2N uninterrupted steps (bitwise on the CPU,
also in a new process; on the GPU as two uninterrupted GPU runs agree, see tests/test_restart.py):
positions, topology, radii, Division and Extrusion counters, lineage, per-cell parameters."""
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import to_numpy

import spherevm as svm
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1, Division, Extrusion, RadiusSchedule
from spherevm.plugins.writers import GSD

pytest.importorskip("gsd")

N_CELLS, REPLICAS, HALF = 24, 2, 30


def _model(kind):
    """Per-cell parameters (the length of the tissue before it grows): explicit ones with FIRE,
    dimensionless ones (resolved from each replica's <A>) with Brownian."""
    n = N_CELLS * REPLICAS
    if kind == "fire":
        return VertexModel(kA=np.linspace(1.0, 2.0, n), kP=1.0, A0=np.linspace(0.9, 1.1, n), P0=3.8)
    return VertexModel.dimensionless(kr=np.linspace(0.5, 1.5, n), p0=np.linspace(3.7, 3.9, n))


def make(kind, device="cpu"):
    """A growing tissue: Division by rate (Hertwig), Extrusion, T1, R keeping the initial <A>."""
    sim = svm.Simulation(device=device, seed=7)
    sim.operations.forces.append(_model(kind))
    sim.operations.updaters.append(T1())
    sim.operations.updaters.append(Division(rule="rate", rate=0.02, dt=1.0))
    sim.operations.updaters.append(Extrusion(area_threshold=0.4))
    sim.operations.updaters.append(RadiusSchedule("constant_area"))      # area: the <A> at the first attach
    sim.operations.integrator = (FIRE(dt=0.05, check_every=7) if kind == "fire"
                                 else Brownian(dt=0.01, T=np.array([0.02, 0.05])))
    return sim


def tiling():
    return svm.init.random_tiling(N_CELLS, replicas=REPLICAS, seed=3)


def record(sim):
    """Everything the two runs must share, as NumPy arrays (positions separately)."""
    vm, div, ext, sched = sim.operations.forces[0], *sim.operations.updaters[1:]
    out = {name: to_numpy(getattr(sim.state, name)).copy() for name in
           ("cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells", "vertex_start", "cell_start")}
    out.update(radius=sim.state.radius_np(), timestep=np.array([sim.timestep]), lineage=div.lineage,
               divisions=div.total_divisions, division_refusals=div.refusals, extrusions=ext.total_extrusions,
               extrusion_refusals=ext.refusals, t1=sim.log("t1_total_flips"), area=sched.target_area,
               counts=sched.counts, **{k: np.asarray(v) for k, v in vm.state_to_save().items()})
    return {k: np.array(v, copy=True) for k, v in out.items()}, to_numpy(sim.state.positions).copy()


def assert_same(a, b, device):
    """``a`` and ``b`` (from :func:`record`) equal; positions bitwise on the CPU, to 1e-9 on the GPU
    (where two uninterrupted runs differ in the last bits; the radii, set on the host from N, do not)."""
    (ra, pa), (rb, pb) = a, b
    assert sorted(ra) == sorted(rb)
    for k in ra:
        assert ra[k].dtype == rb[k].dtype and np.array_equal(ra[k], rb[k]), k
    if device == "cpu":
        assert pa.tobytes() == pb.tobytes()
    else:
        assert np.abs(pa - pb).max() < 1e-9


def halves(kind, device, path):
    """The uninterrupted 2 HALF steps, and the first HALF steps with a checkpoint at the end."""
    whole = make(kind, device)
    whole.state = tiling()
    whole.run(2 * HALF)
    first = make(kind, device)
    first.state = tiling()
    first.operations.writers.append(GSD(trigger=HALF, filename=path))
    first.run(HALF)
    first.operations.writers[0].close()
    return whole, first


@pytest.mark.parametrize("kind", ["fire", "brownian"])
def test_a_growing_tissue_restarts_exactly(kind, device, tmp_path):
    path = tmp_path / "ck.gsd"
    whole, first = halves(kind, device, path)
    n0 = N_CELLS * REPLICAS
    assert n0 < first.state.n_cells < whole.state.n_cells         # it grows in both halves
    second = make(kind, device)
    second.create_state_from_gsd(path)
    assert second.timestep == HALF
    assert_same(record(second), record(first), device)            # the checkpoint holds it all
    second.run(HALF)
    assert_same(record(second), record(whole), device)
    div, ext = whole.operations.updaters[1:3]
    assert len(np.unique(div.lineage)) < len(div.lineage)          # daughters share a lineage
    assert ext.refusals.sum() + ext.total_extrusions.sum() > 0     # Extrusion's counters moved
    assert whole.log("t1_total_flips").sum() > 0
    np.testing.assert_allclose(whole.state.mean_cell_area, tiling().mean_cell_area, rtol=1e-12)


def test_per_cell_parameters_come_from_the_checkpoint_scalars_from_the_script(tmp_path):
    """Per-cell arrays are state (a grown tissue's exist only in the checkpoint); a parameter the
    new script gives as a scalar is the script's; a checkpoint of another State is refused."""
    path = tmp_path / "ck.gsd"
    _, first = halves("fire", "cpu", path)
    saved = first.operations.forces[0]
    again = make("fire")
    again.create_state_from_gsd(path)
    vm = again.operations.forces[0]
    assert vm.kA.tobytes() == saved.kA.tobytes() and vm.A0.tobytes() == saved.A0.tobytes()
    other = svm.Simulation(device="cpu", seed=7)
    other.create_state_from_gsd(path)
    scalar = VertexModel(kA=3.0, kP=1.0, A0=np.ones(first.state.n_cells), P0=3.8)
    other.operations.forces.append(scalar)
    assert scalar.kA.ndim == 0 and float(scalar.kA) == 3.0
    assert scalar.A0.tobytes() == saved.A0.tobytes()
    small = svm.Simulation(device="cpu", seed=7)
    small.state = tiling()
    small.operations.forces.append(_model("fire"))
    with pytest.raises(ValueError, match="another State"):
        small.operations.forces[0].restore_state(saved.state_to_save())


def test_the_radius_schedule_keeps_its_area_across_a_restart(tmp_path):
    """The default area (each replica's <A> at the first attach) is not recomputed from the
    restored sphere: after growth 4 pi R^2 / N rounds to another float for some N, and the next
    R would then differ. An area the new script gives stays the script's."""
    sim = svm.Simulation(device="cpu", seed=7)
    sim.state = tiling()
    sched = RadiusSchedule("constant_area")
    sim.operations.updaters.append(sched)
    area = sched.target_area.copy()
    for c in range(40):              # divide cell c of replica 0 until <A> no longer rounds back
        svm.growth.divide(sim.state, [c], [[0.0, 0.0, 1.0]])
        sched.update(sim, c)
        if sim.state.mean_cell_area[0] != area[0]:
            break
    assert sim.state.mean_cell_area[0] != area[0]
    svm.write_gsd(sim, tmp_path / "r.gsd")
    again = svm.Simulation(device="cpu", seed=7)
    again.operations.updaters.append(RadiusSchedule("constant_area"))
    again.create_state_from_gsd(tmp_path / "r.gsd")
    restored = again.operations.updaters[0]
    assert restored.target_area.tobytes() == area.tobytes()
    assert restored.counts.tolist() == sim.state.cells_per_replica.tolist()
    given = svm.Simulation(device="cpu", seed=7)
    given.operations.updaters.append(RadiusSchedule("constant_area", area=2.0))
    given.create_state_from_gsd(tmp_path / "r.gsd")
    assert given.operations.updaters[0].target_area.tolist() == [2.0, 2.0]


def test_a_growing_tissue_restarts_in_a_new_process(tmp_path):
    path = tmp_path / "ck.gsd"
    whole, _ = halves("fire", "cpu", path)
    script = f"""
import numpy as np, sys
sys.path.insert(0, {os.path.dirname(__file__)!r})
from test_growth_restart import make, record
sim = make("fire")
sim.create_state_from_gsd({str(path)!r})
sim.run({HALF})
arrays, positions = record(sim)
np.savez({str(tmp_path / 'out.npz')!r}, positions=positions, **arrays)
"""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
    subprocess.run([sys.executable, "-c", script], check=True, env=env, cwd=os.getcwd())
    with np.load(tmp_path / "out.npz") as out:
        back = {k: out[k] for k in out.files}
    positions = back.pop("positions")
    assert_same((back, positions), record(whole), "cpu")
