"""Exact restart (issue 13, items 1 and 2): a GSD frame is a checkpoint; continuing from it gives
bitwise the uninterrupted run, also in a fresh process; every run and minimize ends with a frame."""
import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1
from spherevm.plugins.writers import GSD
from spherevm.runs import CheckpointMismatchWarning

from conftest import to_numpy

INTEGRATORS = {
    "brownian": lambda: Brownian(dt=0.01, T=np.array([0.02, 0.05])),
    "active": lambda: Active(dt=0.01, v0=0.3, Dr=0.5, T=0.01),
    "fire": lambda: FIRE(dt=0.05, check_every=7),
}


def make(kind, device, seed=4):
    sim = svm.Simulation(device=device, seed=seed)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.85))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = INTEGRATORS[kind]()
    return sim


@pytest.fixture(scope="module")
def tiling():
    return svm.init.random_tiling(64, replicas=2, seed=3)


# The GPU's per-replica sums (FIRE's power and norms, energies) have the same bits on every run
# (device_common.cuh), so a restart is bitwise the uninterrupted run on both devices.
def same_run(a, b):
    assert final(a) == final(b)


def final(sim):
    return {"positions": to_numpy(sim.state.positions).tobytes(),
            "vertex_neighbors": to_numpy(sim.state.vertex_neighbors).tobytes(),
            "t1": sim.log("t1_total_flips").tolist(), "refused": sim.log("t1_total_refused").tolist(),
            "timestep": sim.timestep}


@pytest.mark.parametrize("kind", sorted(INTEGRATORS))
def test_run_restart_is_bitwise(kind, device, tiling, tmp_path):
    whole = make(kind, device)
    whole.state = tiling
    whole.run(300)
    path = tmp_path / "ck.gsd"
    first = make(kind, device)
    first.state = tiling
    first.operations.writers.append(GSD(150, path))
    first.run(150)
    second = make(kind, device)
    second.create_state_from_gsd(path)
    assert second.timestep == 150
    second.run(150)
    same_run(second, whole)
    assert sum(final(whole)["t1"]) > 0          # the test goes through T1 flips
    if kind == "fire":
        fa, fb = whole.operations.integrator, second.operations.integrator
        assert fa.iteration == fb.iteration
        for name in ("velocities", "replica_dt"):
            x, y = to_numpy(getattr(fa, name)), to_numpy(getattr(fb, name))
            assert x.tobytes() == y.tobytes(), name


def checkpoint_after(kind, tiling, steps, path):
    """``path``, a checkpoint of ``make(kind, "cpu")`` on ``tiling`` after ``steps`` steps."""
    sim = make(kind, "cpu")
    sim.state = tiling
    sim.run(steps)
    svm.write_gsd(sim, path)
    return path


def bare_restart(path):
    """A CPU Simulation without operations, restored from ``path``."""
    sim = svm.Simulation(device="cpu", seed=4)
    sim.create_state_from_gsd(path)
    return sim


def test_operations_attached_after_the_state_pick_up_their_state(tiling, tmp_path):
    whole = make("active", "cpu")
    whole.state = tiling
    whole.run(60)
    second = bare_restart(checkpoint_after("active", tiling, 30, tmp_path / "ck.gsd"))
    second.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.85))
    second.operations.updaters.append(T1())
    second.operations.integrator = INTEGRATORS["active"]()
    second.run(30)
    assert final(second) == final(whole)


def test_a_checkpoint_restored_into_other_operations_says_so_once(tiling, tmp_path):
    """Written with T1 + Brownian + VertexModel, restored with FIRE alone: the first run warns, once,
    naming the saved state no operation took (T1's; Brownian and a scalar VertexModel save none) and
    the operation that started fresh (FIRE); the unclaimed state stays in later checkpoints."""
    second = bare_restart(checkpoint_after("brownian", tiling, 20, tmp_path / "ck.gsd"))
    second.operations.integrator = FIRE()
    with pytest.warns(CheckpointMismatchWarning) as caught:
        second.run(3)
    assert len(caught) == 1 and caught[0].filename == __file__
    assert str(caught[0].message).startswith(
        f"{tmp_path / 'ck.gsd'}: saved state of updaters.0.T1 found no operation (kept for the next checkpoint); "
        "integrator.FIRE found no saved state and started fresh. An operation takes its saved state by its key")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        second.run(3)                                          # said once
        assert "op/updaters.0.T1/total_flips" in second.checkpoint()
        matching = make("brownian", "cpu")                     # the same operations: nothing to say
        matching.create_state_from_gsd(tmp_path / "ck.gsd")
        matching.run(3)
        replaced = make("fire", "cpu")                         # a State set after the restore drops the file's
        replaced.create_state_from_gsd(tmp_path / "ck.gsd")
        replaced.state = tiling
        replaced.minimize(max_steps=3)


def test_restart_in_a_new_process(tiling, tmp_path):
    whole = make("fire", "cpu")
    whole.state = tiling
    whole.run(200)
    first = make("fire", "cpu")
    first.state = tiling
    first.run(100)
    svm.write_gsd(first, tmp_path / "ck.gsd")
    script = f"""
import numpy as np, spherevm as svm, sys
sys.path.insert(0, {os.path.dirname(__file__)!r})
from test_restart import make
sim = make("fire", "cpu")
sim.create_state_from_gsd({str(tmp_path / 'ck.gsd')!r})
sim.run(100)
np.save({str(tmp_path / 'out.npy')!r}, sim.state.positions)
"""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
    subprocess.run([sys.executable, "-c", script], check=True, env=env, cwd=os.getcwd())
    assert np.load(tmp_path / "out.npy").tobytes() == whole.state.positions.tobytes()


def minimizer(tiling, device="cpu"):
    sim = svm.Simulation(device=device, seed=1)
    sim.state = tiling
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.85))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.05)
    return sim


def test_minimize_resume_equals_one_minimize(tiling):
    whole = minimizer(tiling)
    r_whole = whole.minimize(force_tol=1e-12, max_steps=600)
    parts = minimizer(tiling)
    parts.minimize(force_tol=1e-12, max_steps=300)
    r_parts = parts.minimize(force_tol=1e-12, max_steps=300, resume=True)
    assert parts.state.positions.tobytes() == whole.state.positions.tobytes()
    assert np.array_equal(r_parts.steps, r_whole.steps) and list(r_parts.reason) == list(r_whole.reason)
    assert parts.timestep == whole.timestep
    # the default starts FIRE afresh (today's behaviour): a different path
    fresh = minimizer(tiling)
    fresh.minimize(force_tol=1e-12, max_steps=300)
    fresh.minimize(force_tol=1e-12, max_steps=300)
    assert fresh.state.positions.tobytes() != whole.state.positions.tobytes()


def test_minimize_resume_from_a_checkpoint(device, tiling, tmp_path):
    whole = minimizer(tiling, device)
    whole.minimize(force_tol=1e-12, max_steps=400, narrow=False)
    first = minimizer(tiling, device)
    first.operations.writers.append(GSD(10_000, tmp_path / "ck.gsd"))
    first.minimize(force_tol=1e-12, max_steps=200)
    second = minimizer(tiling, device)
    second.create_state_from_gsd(tmp_path / "ck.gsd")
    second.minimize(force_tol=1e-12, max_steps=200, resume=True)
    same_run(second, whole)
    assert second.log("t1_total_flips").tolist() == whole.log("t1_total_flips").tolist()


def test_final_frame_is_written(tiling, tmp_path):
    sim = minimizer(tiling)
    path = tmp_path / "m.gsd"
    sim.operations.writers.append(GSD(svm.trigger.Periodic(200), path))
    result = sim.minimize(force_tol=1e-6, max_steps=5000)
    with svm.gsdio.Reader(path) as r:
        assert r.step(-1) == sim.timestep
        assert r.state(-1).positions.tobytes() == sim.state.positions.tobytes()
    assert int(result.steps.max()) % 200 != 0 or True
    # a writer that does not want it
    sim2 = minimizer(tiling)
    sim2.operations.writers.append(GSD(svm.trigger.Periodic(200), tmp_path / "n.gsd", final=False))
    sim2.run(250)
    with svm.gsdio.Reader(tmp_path / "n.gsd") as r:
        assert r.step(-1) == 200


def test_write_gsd_one_shot(tiling, tmp_path):
    sim = minimizer(tiling)
    sim.run(5)
    path = svm.write_gsd(sim, tmp_path / "one.gsd")
    assert svm.gsdio.n_frames(path) == 1
    assert svm.init.from_gsd(path).positions.tobytes() == sim.state.positions.tobytes()


def test_gsd_writer_given_a_directory(tiling, tmp_path):
    sim = minimizer(tiling)
    with pytest.raises(ValueError, match="is a directory; give a file name"):
        svm.write_gsd(sim, tmp_path)


class Counter(svm.plugins.Updater):
    """A user plugin with state, declared through checkpoint_fields."""
    checkpoint_fields = ("count",)

    def attach(self, simulation):
        super().attach(simulation)
        self.count = np.zeros(simulation.state.n_replicas, dtype=np.int64)

    def update(self, simulation, timestep):
        self.count += 1


def test_user_plugin_state_is_restored(tiling, tmp_path):
    sim = minimizer(tiling)
    sim.operations.updaters.append(Counter())
    sim.run(7)
    svm.write_gsd(sim, tmp_path / "c.gsd")
    again = minimizer(tiling)
    again.operations.updaters.append(Counter())
    again.create_state_from_gsd(tmp_path / "c.gsd")
    assert again.operations.updaters[1].count.tolist() == [7, 7]


def _cli(*argv, cwd=None):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "spherevm", *argv], capture_output=True, text=True, env=env,
                          cwd=cwd)


def test_cli_minimize_restart_continues_bitwise(tmp_path):
    common = ("--cells", "16", "--replicas", "2", "-q")
    whole = _cli("minimize", *common, "--max-steps", "600", "--out", str(tmp_path / "w.gsd"))
    first = _cli("minimize", *common, "--max-steps", "300", "--out", str(tmp_path / "a.gsd"))
    second = _cli("minimize", "-q", "--restart", str(tmp_path / "a.gsd"), "--max-steps", "300",
                  "--out", str(tmp_path / "b.gsd"))
    assert whole.returncode == first.returncode == second.returncode == 0, second.stderr
    assert second.stdout == whole.stdout
    a, b = svm.init.from_gsd(tmp_path / "w.gsd"), svm.init.from_gsd(tmp_path / "b.gsd")
    assert a.positions.tobytes() == b.positions.tobytes()


def test_cli_dynamics_restart_continues_the_timestep(tmp_path):
    out = _cli("dynamics", "--cells", "16", "--replicas", "1", "--steps", "40", "--relax", "50", "-q",
               "--out", str(tmp_path / "d.gsd"))
    assert out.returncode == 0, out.stderr
    again = _cli("dynamics", "--restart", str(tmp_path / "d.gsd"), "--steps", "40", "-q",
                 "--out", str(tmp_path / "e.gsd"))
    assert again.returncode == 0, again.stderr
    with svm.gsdio.Reader(tmp_path / "d.gsd") as r, svm.gsdio.Reader(tmp_path / "e.gsd") as s:
        assert s.step(-1) == r.step(-1) + 40


@pytest.mark.parametrize("argv, flag", [
    (("minimize", "--out", "/proc/x.gsd"), "--out"),
    (("dynamics", "--csv", "/no/dir/x.csv"), "--csv"),
    (("minimize", "--restart", "/no/such.gsd"), "--restart"),
])
def test_cli_bad_paths_are_usage_errors_naming_the_flag(argv, flag):
    out = _cli(*argv, "-q")
    assert out.returncode == 2 and f"argument {flag}" in out.stderr, out.stderr


# ------------------------------------------------------------------ issue 36, item 3: history is never overwritten
def _steps_and_positions(path):
    with svm.gsdio.Reader(path) as r:
        return [r.step(i) for i in range(len(r))], [r.state(i).positions.tobytes() for i in range(len(r))]


def test_cli_minimize_restart_into_its_own_file_appends(tmp_path):
    path = str(tmp_path / "a.gsd")
    common = ("--write-every", "100", "--force-tol", "0", "--energy-tol", "0", "-q")
    first = _cli("minimize", "--cells", "16", "--replicas", "2", "--max-steps", "300", "--out", path, *common)
    assert first.returncode == 0, first.stderr
    steps, frames = _steps_and_positions(path)
    again = _cli("minimize", "--restart", path, "--max-steps", "200", "--out", path, *common)
    assert again.returncode == 0, again.stderr
    more_steps, more_frames = _steps_and_positions(path)
    assert steps == [0, 100, 200, 300] and more_steps == [0, 100, 200, 300, 400, 500]   # no second frame at 300
    assert more_frames[:4] == frames                                                      # the history is kept
    whole = _cli("minimize", "--cells", "16", "--replicas", "2", "--max-steps", "500", *common)
    assert again.stdout == whole.stdout


def test_cli_existing_outputs_need_overwrite(tmp_path):
    path = tmp_path / "b.gsd"
    run = ("minimize", "--cells", "16", "--replicas", "1", "--max-steps", "20", "-q", "--out", str(path))
    assert _cli(*run).returncode == 0
    before = path.read_bytes()
    refused = _cli(*run)
    assert refused.returncode == 2 and path.read_bytes() == before
    assert f"argument --out: {str(path)!r} exists; give --overwrite to replace it" in refused.stderr
    assert _cli(*run, "--seed", "1", "--overwrite").returncode == 0 and path.read_bytes() != before
    steps, frames = _steps_and_positions(path)
    kept = _cli("minimize", "--restart", str(path), "--seed", "1", "--max-steps", "20", "-q", "--out", str(path),
                "--overwrite")                                         # the --restart file is appended to, never replaced
    assert kept.returncode == 0, kept.stderr
    assert _steps_and_positions(path)[1][:2] == frames and _steps_and_positions(path)[0] == steps + [40]


def test_cli_dynamics_restart_into_its_own_file_appends(tmp_path):
    path = str(tmp_path / "d.gsd")
    assert _cli("dynamics", "--cells", "16", "--replicas", "1", "--steps", "40", "--relax", "50", "-q",
                "--out", path).returncode == 0
    steps, frames = _steps_and_positions(path)
    refused = _cli("dynamics", "--restart", path, "--steps", "40", "-q", "--out", path)
    assert refused.returncode == 2 and "argument --csv" in refused.stderr and "give --overwrite" in refused.stderr
    again = _cli("dynamics", "--restart", path, "--steps", "40", "-q", "--out", path, "--overwrite")
    assert again.returncode == 0, again.stderr
    more_steps, more_frames = _steps_and_positions(path)
    assert more_frames[:len(frames)] == frames and more_steps[:len(steps)] == steps
    assert more_steps[-1] == steps[-1] + 40 and np.all(np.diff(more_steps) > 0)


def test_gsd_writer_appends_to_the_file_the_simulation_was_restored_from(tiling, tmp_path):
    path = tmp_path / "c.gsd"
    sim = minimizer(tiling)
    sim.operations.writers.append(GSD(50, path))
    sim.minimize(max_steps=100)
    steps, frames = _steps_and_positions(path)
    again = minimizer(tiling)
    again.create_state_from_gsd(path)
    again.operations.writers.append(GSD(50, path))                     # the default mode appends here
    again.minimize(max_steps=100, resume=True)
    more_steps, more_frames = _steps_and_positions(path)
    assert more_frames[:len(frames)] == frames and more_steps == steps + [150, 200]
    for mode, frame, message in (("wb", -1, "mode='wb' would erase the frames it continues"),
                                 (None, 0, "ends at step 200, but the Simulation was restored from its frame of step 0")):
        other = minimizer(tiling)
        other.create_state_from_gsd(path, frame=frame)
        other.operations.writers.append(GSD(50, path, mode=mode))
        with pytest.raises(ValueError, match=re.escape(message)):
            other.run(1)
    assert _steps_and_positions(path)[0] == more_steps
