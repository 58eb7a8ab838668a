"""The finite-temperature protocol and the `spherevm dynamics` command."""
import numpy as np
import pytest

from spherevm import cli
from spherevm.protocols import glassy_dynamics


def test_glassy_dynamics_hot_small_sphere_relaxes():
    # dt = 0.02 (the same time as 3000 steps of 0.05): at T = 0.05 a step of 0.05 moves vertices
    # past the T1 threshold and about one run in seven ends in an exploding step, seed-dependently
    res = glassy_dynamics(16, 3.9, 0.0, T=[0.05, 0.05], dt=0.02, steps=7500, replicas=2, relax_steps=500,
                          device="cpu")
    assert res.lag[0] == 0 and np.all(np.diff(res.lag) > 0)
    assert res.msd[0] == 0 and res.msd[-1] > res.msd[1] > 0
    assert res.self_overlap[0] == 1.0 and res.self_overlap[-1] < 1 / np.e
    assert 0 < res.tau_alpha < res.lag[-1]
    assert res.msd_per_replica.shape == (len(res.lag), 2) and len(res.tau_alpha_per_replica) == 2


def test_an_initial_state_of_several_sizes_runs_as_one_ensemble():
    """``initial_state`` gives the same run as the built-in tilings; sizes mixed in one State each
    keep their own curves (cell-weighted averages over replicas of one size)."""
    from spherevm import State, init
    kw = dict(T=[0.05, 0.05], dt=0.02, steps=400, relax_steps=100, seed=3, device="cpu")
    built = glassy_dynamics(16, 3.9, 0.0, replicas=2, **kw)
    given = glassy_dynamics(None, 3.9, 0.0, initial_state=init.random_tiling(16, replicas=2, seed=3), **kw)
    assert np.array_equal(built.msd_per_replica, given.msd_per_replica)
    assert np.array_equal(built.self_overlap_per_replica, given.self_overlap_per_replica)
    mixed = State.concatenate([init.random_tiling(16, replicas=2, seed=3), init.random_tiling(40, seed=4)])
    res = glassy_dynamics(None, 3.9, 0.0, initial_state=mixed, **{**kw, "T": [0.05, 0.05, 0.05]})
    assert res.msd_per_replica.shape == (len(res.lag), 3) and len(res.tau_alpha_per_replica) == 3
    weights = np.array([16, 16, 40])
    assert np.allclose(res.msd, (res.msd_per_replica * weights).sum(axis=1) / weights.sum(), rtol=1e-12)
    with pytest.raises(TypeError, match="initial_state"):
        glassy_dynamics(None, 3.9, 0.0, initial_state="tiling.gsd", **kw)


def test_colder_is_slower():
    hot, cold = (glassy_dynamics(16, 3.9, 0.0, T=T, dt=0.05, steps=1500, replicas=2, relax_steps=300, seed=1,
                                 device="cpu") for T in (0.05, 0.005))
    assert cold.msd[-1] < hot.msd[-1]


def test_dynamics_cli_writes_csv_and_gsd(tmp_path, capsys):
    out = tmp_path / "d.gsd"
    code = cli.main(["dynamics", "--cells", "16", "--replicas", "2", "--steps", "300", "--relax", "200",
                     "--T", "0.02", "--out", str(out), "-q"])
    assert code == 0
    text = capsys.readouterr().out
    assert "tau_alpha =" in text
    rows = (tmp_path / "d.csv").read_text().splitlines()
    assert rows[0] == "time,msd,self_overlap" and len(rows) > 10
    import gsd.hoomd
    with gsd.hoomd.open(out) as traj:
        assert len(traj) > 3


def test_dynamics_gsd_starts_at_production(tmp_path, capsys):
    """The GSD's first frame is at the end of relaxation + equilibration (issue 14.7): the result and
    the command say which step that is, and the lags count from it."""
    import gsd.hoomd
    from spherevm.analysis import Trajectory, msd
    out = tmp_path / "p.gsd"
    res = glassy_dynamics(16, 3.9, 0.0, T=0.02, dt=0.05, steps=200, replicas=2, relax_steps=150, seed=2,
                          device="cpu", out=str(out), equilibrate_steps=30)
    with gsd.hoomd.open(out) as traj:
        steps = [int(f.configuration.step) for f in traj]
    relaxed = res.production_start - 30
    assert 0 < relaxed <= 150                         # FIRE stopped somewhere in its 150 steps
    assert steps[0] == res.production_start and steps[-1] == res.production_start + 200
    from_file = Trajectory.from_gsd(out)
    lag, m = msd(from_file)
    assert lag[0] == 0 and lag[-1] == 200              # lags from the first frame, in steps
    i = int(np.flatnonzero(res.lag == 200 * 0.05)[0])
    assert m[-1] == pytest.approx(res.msd[i], rel=1e-12)   # the same frames as the recording
    code = cli.main(["dynamics", "--cells", "16", "--replicas", "1", "--steps", "50", "--relax", "40",
                     "--T", "0.02", "--out", str(tmp_path / "c.gsd")])
    assert code == 0
    err = capsys.readouterr().err
    with gsd.hoomd.open(tmp_path / "c.gsd") as traj:
        first = int(traj[0].configuration.step)
    assert first > 0 and f"c.gsd's first frame is step {first}, the start of production" in err


@pytest.mark.parametrize("argv", [["--T", "-1"], ["--dt", "0"], ["--steps", "0"], ["--cells", "3"]])
def test_dynamics_cli_bad_input(argv, capsys):
    assert cli.main(["dynamics", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("spherevm: error:") and "Traceback" not in err[0]
