"""HOOMD-blue conventions (issue 14.7, docs/hoomd.md): writer argument order, Trigger.compute, the
Logger, FIRE's default step; the old spellings keep working. HOOMD habits (issue 35.4): Table's
positional logger, ``sim.operations += op``, ``tps``, ``walltime``, ``write_at_start``,
``Logger(categories=)``."""
import io
import warnings

import gsd.hoomd
import numpy as np
import pytest

import spherevm as svm
from conftest import fire_simulation
from spherevm.logging import Logger
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1
from spherevm.plugins.writers import GSD, Table
from spherevm.trigger import And, Or, Periodic, Trigger


def _sim(replicas=2):
    return fire_simulation(replicas=replicas, seed=1)


def _steps(path):
    with gsd.hoomd.open(path, "r") as f:
        return [int(frame.configuration.step) for frame in f]


# ---------------------------------------------------------------------- writer argument order
@pytest.mark.parametrize("make", [
    lambda p: GSD(5, p),                                  # hoomd.write.GSD(trigger, filename)
    lambda p: GSD(Periodic(5), filename=p),
    lambda p: GSD(trigger=5, filename=p),
    lambda p: GSD(filename=p, trigger=Periodic(5)),
])
def test_gsd_takes_the_trigger_first(make, tmp_path):
    path = str(tmp_path / "a.gsd")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        writer = make(path)
    assert writer.filename == path and writer.trigger(10) and not writer.trigger(7)
    sim = _sim()
    sim.operations.writers.append(writer)
    sim.run(12)
    writer.close()
    assert _steps(path) == [0, 5, 10, 12]          # 12: the final frame


@pytest.mark.parametrize("args,kwargs", [(("old.gsd",), {"trigger": 5}), (("old.gsd", 5), {})])
def test_gsd_old_order_still_works_and_warns(args, kwargs, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.warns(DeprecationWarning, match=r"GSD\(trigger, path\)"):
        writer = GSD(*args, **kwargs)
    assert writer.filename == "old.gsd" and writer.trigger(5) and not writer.trigger(4)
    with pytest.warns(DeprecationWarning):
        assert GSD("only.gsd").trigger(1000) and not GSD("only.gsd").trigger(999)   # the default trigger


def test_gsd_argument_mistakes_are_named(tmp_path):
    with pytest.raises(TypeError, match="trigger both by position and by keyword"):
        GSD(5, tmp_path / "a.gsd", trigger=10)
    with pytest.raises(TypeError, match="filename both"):
        GSD(5, tmp_path / "a.gsd", filename=tmp_path / "b.gsd")
    with pytest.raises(TypeError, match=r"at most 2 positional arguments \(trigger, filename\)"):
        GSD(5, tmp_path / "a.gsd", "wb")
    with pytest.raises(TypeError, match="path both"):
        Table(5, tmp_path / "a.csv", path=tmp_path / "b.csv")
    with pytest.raises(ValueError, match="filename must be a non-empty path"):
        GSD(5)


def test_table_takes_the_trigger_first(tmp_path):
    path = tmp_path / "t.csv"
    sim = _sim()
    sim.operations.writers.append(Table(4, path, quantities=["energy_per_cell"]))
    with pytest.warns(DeprecationWarning):
        old = Table(str(tmp_path / "old.csv"), trigger=4, quantities=["energy_per_cell"])
    sim.operations.writers.append(old)
    sim.run(8)
    for w in sim.operations.writers:
        w.close()
    new_rows = path.read_text().splitlines()
    assert new_rows[0] == "timestep,replica,energy_per_cell"
    assert [r.split(",")[0] for r in new_rows[1:]] == ["0", "0", "4", "4", "8", "8"]
    assert (tmp_path / "old.csv").read_text() == path.read_text()


# ---------------------------------------------------------------------- triggers
def test_builtin_triggers_decide_in_compute():
    t = Periodic(3, phase=1)
    assert [t.compute(s) for s in range(8)] == [t(s) for s in range(8)] == [s >= 1 and (s - 1) % 3 == 0
                                                                            for s in range(8)]
    both = And([Periodic(2), Periodic(3)])                 # HOOMD's list form
    assert both.compute(6) and not both.compute(4) and And(Periodic(2), Periodic(3)).compute(12)
    assert [s for s in range(10) if Or([Periodic(4), Periodic(6)])(s)] == [0, 4, 6, 8]
    with pytest.raises(NotImplementedError, match="must implement compute"):
        Trigger()(3)


class _Squares(Trigger):          # written as for HOOMD: compute(timestep)
    def compute(self, timestep):
        return int(round(timestep ** 0.5)) ** 2 == timestep


class _OldSquares(Trigger):       # written for spherevm 0.1: __call__
    def __call__(self, timestep):
        return int(round(timestep ** 0.5)) ** 2 == timestep


@pytest.mark.parametrize("cls", [_Squares, _OldSquares])
def test_user_triggers_drive_a_writer(cls, tmp_path):
    sim = _sim(replicas=1)
    writer = GSD(cls(), tmp_path / "sq.gsd", final=False)
    sim.operations.writers.append(writer)
    sim.run(20)
    writer.close()
    assert _steps(tmp_path / "sq.gsd") == [0, 1, 4, 9, 16]
    assert [s for s in range(20) if (cls() & ~Periodic(2))(s)] == [1, 9]


# ---------------------------------------------------------------------- the Logger
def test_logger_chooses_what_the_gsd_logs(tmp_path):
    sim = _sim()
    t1 = sim.operations.updaters[0]
    logger = Logger(["energy_per_cell"])
    logger.add(t1)                                          # every loggable of an operation
    logger.add(sim, quantities=["mean_shape_index"])
    logger["twice_energy"] = lambda s: 2 * s.log("energy")  # a custom quantity
    assert set(t1.loggables) <= set(logger) and logger.names[0] == "energy_per_cell" and len(logger) >= 4
    path = tmp_path / "log.gsd"
    sim.operations.writers.append(GSD(10, path, logger=logger))
    sim.run(30)
    sim.operations.writers[0].close()
    with gsd.hoomd.open(path, "r") as f:
        last = f[-1]
        logged = {k for k in last.log if not k.startswith(("particles/", "bonds/"))}
        assert logged == set(logger.names)                  # log/<name>, nothing else
        np.testing.assert_allclose(last.log["twice_energy"], 2 * sim.log("energy"), rtol=1e-15)
        np.testing.assert_allclose(last.log["energy_per_cell"], sim.log("energy_per_cell"), rtol=1e-15)
        np.testing.assert_array_equal(last.log["t1_total_flips"], sim.log("t1_total_flips"))


def test_gsd_log_takes_a_logger_as_hoomd_3(tmp_path):
    logger = Logger(["energy"])
    assert GSD(1, tmp_path / "a.gsd", log=logger).logger is logger
    assert GSD(1, tmp_path / "a.gsd", log=["energy", "max_force"]).log == ("energy", "max_force")


def test_logger_drives_a_table(tmp_path):
    sim = _sim()
    logger = Logger("mean_shape_index")
    logger["double_index"] = lambda s: 2 * np.asarray(s.log("mean_shape_index"))
    table = Table(5, tmp_path / "t.csv", logger=logger)
    sim.operations.writers.append(table)
    sim.run(5)
    table.close()
    rows = [r.split(",") for r in (tmp_path / "t.csv").read_text().splitlines()]
    assert rows[0] == ["timestep", "replica", "mean_shape_index", "double_index"]
    for row in rows[1:]:
        assert float(row[3]) == pytest.approx(2 * float(row[2]), rel=1e-11)


def test_logger_mistakes_fail_before_writing(tmp_path):
    sim = _sim()
    with pytest.raises(ValueError, match=r"T1 has no loggable\(s\) \['energy'\]"):
        Logger().add(sim.operations.updaters[0], quantities=["energy"])
    with pytest.raises(TypeError, match="no loggables"):
        Logger().add(object())
    with pytest.raises(TypeError, match="callable"):
        Logger()["x"] = 3.0
    with pytest.raises(KeyError, match="not logged"):
        Logger(["energy"]).remove("max_force")
    with pytest.raises(ValueError, match="not both"):
        GSD(1, tmp_path / "x.gsd", logger=Logger(), log=["energy"])
    with pytest.raises(ValueError, match="not both"):
        Table(1, logger=Logger(), quantities=["energy"])
    # an unknown name: the Table fails before its header, the GSD before creating its file
    table = Table(1, tmp_path / "t.csv", logger=Logger(["energy", "nope"]))
    with pytest.raises(ValueError, match=r"Table writer: unknown loggable\(s\) \['nope'\]"):
        table.write(sim, 0)
    assert not (tmp_path / "t.csv").exists()
    clash = Logger()
    clash["energy"] = lambda s: 0.0
    with pytest.raises(ValueError, match="custom quantity.*name of a loggable"):
        GSD(1, tmp_path / "c.gsd", logger=clash).write(sim, 0)
    assert not (tmp_path / "c.gsd").exists()


# ---------------------------------------------------------------------- FIRE's default step
def test_fire_default_dt_is_the_documented_one():
    from spherevm.cli import build_parser
    fire = svm.plugins.integrators.FIRE()
    assert fire.dt == 0.02 and fire.dt_max == pytest.approx(0.2, rel=1e-15)
    assert build_parser().parse_args(["minimize"]).dt == fire.dt


# ---------------------------------------------------------------------- HOOMD habits (issue 35.4)
def test_table_takes_hoomds_positional_logger_and_output(tmp_path, capsys):
    sim = _sim()
    logger = Logger(["mean_shape_index"], categories=["scalar", "string"])   # HOOMD's usual Table logger
    buffer = io.StringIO()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        to_stdout = Table(Periodic(5), logger)                               # hoomd.write.Table(trigger, logger)
        to_buffer = Table(Periodic(5), logger, buffer)                       # ... output=buffer
        by_keyword = Table(trigger=Periodic(5), logger=logger, output=tmp_path / "t.csv")
    for writer in (to_stdout, to_buffer, by_keyword):
        assert writer.logger is logger and writer.trigger(5) and not writer.trigger(4)
        sim.operations.writers.append(writer)
    sim.run(5)
    for writer in (to_stdout, to_buffer, by_keyword):
        writer.close()
    text = buffer.getvalue()
    assert not buffer.closed and text.splitlines()[0] == "timestep,replica,mean_shape_index"
    assert [r.split(",")[:2] for r in text.splitlines()[1:]] == [["0", "0"], ["0", "1"], ["5", "0"], ["5", "1"]]
    assert capsys.readouterr().out == text == (tmp_path / "t.csv").read_text()


def test_table_argument_mistakes_fail_at_construction():
    with pytest.raises(TypeError, match=r"path must be a file path, an open text file or None \(standard output\), "
                                        r"got float; HOOMD's order is Table\(trigger, logger, output\)"):
        Table(5, 3.0)
    with pytest.raises(TypeError, match="got Logger; HOOMD's order"):
        Table(5, path=Logger())
    with pytest.raises(TypeError, match="logger both by position and by keyword"):
        Table(5, Logger(), logger=Logger())
    with pytest.raises(TypeError, match="path and output"):
        Table(5, path="a.csv", output="b.csv")


def test_logger_categories_must_include_scalar():
    assert Logger("energy", categories="scalar").names == ("energy",)
    with pytest.raises(ValueError, match=r"categories=\['particle'\]\): spherevm logs scalars only .* "
                                         r"GSD\(cell_quantities=...\)"):
        Logger(categories=["particle"])


def test_operations_add_and_remove_dispatch_by_kind():
    sim = svm.Simulation(device="cpu", seed=1)
    sim.state = svm.init.random_tiling(16, replicas=2, seed=1)
    force, t1, fire, brownian = VertexModel.dimensionless(kr=1.0, p0=3.8), T1(), FIRE(), Brownian(dt=0.01, T=0.0)
    writer = Table(5, io.StringIO())
    for op in (force, t1, fire, writer):
        sim.operations += op
    assert list(sim.operations.forces) == [force] and list(sim.operations.updaters) == [t1]
    assert sim.operations.integrator is fire and list(sim.operations.writers) == [writer]
    assert all(op._simulation is sim for op in (force, t1, fire, writer)) and t1 in sim.operations
    sim.operations.add(brownian)                      # an integrator replaces the one there
    assert sim.operations.integrator is brownian and fire._simulation is None and fire not in sim.operations
    sim.operations -= t1
    sim.operations.remove(brownian)
    assert len(sim.operations.updaters) == 0 and t1._simulation is None and sim.operations.integrator is None
    with pytest.raises(ValueError, match="this T1 is not in sim.operations"):
        sim.operations.remove(t1)
    with pytest.raises(ValueError, match="this FIRE is not in sim.operations"):
        sim.operations -= fire
    with pytest.raises(TypeError, match=r"sim.operations.add: expected a spherevm.plugins Force, Integrator, "
                                        r"Updater or Writer, got list"):
        sim.operations += [t1]


def test_tps_and_walltime_time_the_last_run():
    sim = _sim()
    assert sim.tps == 0.0 and sim.walltime == 0.0                    # before any run
    seen = []

    class Clock(svm.plugins.Writer):
        def write(self, simulation, timestep):
            seen.append((timestep, simulation.walltime, simulation.tps))

    sim.operations.writers.append(Clock(10))
    sim.run(30)
    first = sim.walltime
    assert first > 0 and sim.tps == 30 / first                       # fixed once the run has ended
    assert sim.walltime == first
    walls = [w for _, w, _ in seen]
    assert [t for t, _, _ in seen] == [0, 10, 20, 30] and walls == sorted(walls) and seen[0][2] == 0.0
    assert all(tps > 0 for _, _, tps in seen[1:])
    assert sim.log("walltime") == first and sim.log("tps") == sim.tps   # loggables, as in HOOMD
    sim.run(0)                                                      # every call starts the clock again
    assert sim.tps == 0.0 and sim.walltime < first
    sim.minimize(max_steps=20)
    assert sim.walltime > 0 and sim.tps > 0


@pytest.mark.parametrize("write_at_start,steps", [(True, [0, 5, 10, 15, 20]), (False, [5, 10, 15, 20])])
def test_write_at_start(write_at_start, steps, tmp_path):
    """True (the default) writes the timestep a run starts on, once; False is HOOMD's default."""
    sim = _sim(replicas=1)
    writer = GSD(5, tmp_path / "w.gsd", final=False)
    sim.operations.writers.append(writer)
    sim.run(10, write_at_start=write_at_start)
    sim.run(10, write_at_start=True)                  # step 10 is written already: not twice
    writer.close()
    assert _steps(tmp_path / "w.gsd") == steps
