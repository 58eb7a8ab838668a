"""The ``spherevm`` command line: in-process through ``spherevm.cli.main`` and once as a subprocess."""
from __future__ import annotations

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import spherevm as svm
from spherevm import cli

EXAMPLE = pathlib.Path(__file__).parent / "plugin_example"


def _rows(text):
    """The data rows of the per-replica table (after its header line)."""
    lines = [line for line in text.splitlines() if line.strip()]
    assert lines and lines[0].split()[0] == "replica", text
    return [line.split() for line in lines[1:]]


def _assert_one_line_error(captured, rc, code=2):
    assert rc == code
    err_lines = captured.err.strip().splitlines()
    assert len(err_lines) == 1, captured.err
    assert err_lines[0].startswith("spherevm: error: "), captured.err
    assert "Traceback" not in captured.err + captured.out


# ------------------------------------------------------------------------------------ minimize
def test_minimize_prints_one_row_per_replica_and_writes_gsd(tmp_path, capsys):
    pytest.importorskip("gsd")
    out = tmp_path / "run.gsd"
    rc = cli.main(["minimize", "--cells", "16", "--replicas", "3", "--max-steps", "300", "--seed", "2",
                   "--device", "cpu", "--out", str(out), "--write-every", "100"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    rows = _rows(captured.out)
    assert [r[0] for r in rows] == ["0", "1", "2"]
    for r in rows:
        assert len(r) == 7
        float(r[1]), float(r[2]), float(r[3])   # energy/cell, shape index, max|F| parse as numbers
        assert r[4] in ("yes", "no")
        assert 0 <= int(r[6]) <= 300
    # progress and summary on stderr, not spamming
    assert "minimize: step" in captured.err
    assert len(captured.err.splitlines()) <= 10
    assert "Traceback" not in captured.err
    # the trajectory: first frame, every 100 steps, and the last one
    assert out.is_file() and out.stat().st_size > 0
    import gsd.hoomd
    with gsd.hoomd.open(str(out), "r") as traj:
        steps = [int(frame.configuration.step) for frame in traj]
    last = max(int(r[6]) for r in rows)
    assert steps[0] == 0 and steps[-1] == last
    assert steps == sorted(set(steps))
    state = svm.init.from_gsd(str(out))
    assert state.n_replicas == 3 and state.n_cells == 3 * 16


def test_minimize_defaults_are_quick_and_converge(capsys):
    rc = cli.main(["minimize", "--quiet", "--device", "cpu"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    rows = _rows(captured.out)
    assert len(rows) == 4
    assert all(r[4] == "yes" for r in rows), captured.out
    assert captured.err == ""   # --quiet


def test_write_every_zero_writes_first_and_last_frames(tmp_path, capsys):
    pytest.importorskip("gsd")
    out = tmp_path / "two.gsd"
    rc = cli.main(["minimize", "-N", "12", "-R", "1", "--max-steps", "40", "--device", "cpu", "-q",
                   "--force-tol", "0", "--energy-tol", "0", "--out", str(out), "--write-every", "0"])
    assert rc == 0
    import gsd.hoomd
    with gsd.hoomd.open(str(out), "r") as traj:
        assert [int(f.configuration.step) for f in traj] == [0, 40]
    assert _rows(capsys.readouterr().out)[0][5] == "max_steps"


@pytest.mark.parametrize("argv", [
    ["minimize", "--cells", "3"],
    ["minimize", "--cells", "many"],
    ["minimize", "--replicas", "0"],
    ["minimize", "--p0", "-1"],
    ["minimize", "--kr", "-0.5"],
    ["minimize", "--dt", "0"],
    ["minimize", "--dt", "-0.1"],
    ["minimize", "--dt", "nan"],
    ["minimize", "--max-steps", "-5"],
    ["minimize", "--device", "tpu"],
    ["minimize", "--out", "/no/such/folder/run.gsd"],
    ["minimize", "--no-such-option"],
    ["frobnicate"],
    [],
])
def test_bad_arguments_give_one_line_and_status_2(argv, capsys):
    rc = cli.main(argv)
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert captured.out == ""


def test_out_is_a_directory(tmp_path, capsys):
    rc = cli.main(["minimize", "--out", str(tmp_path)])
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert "directory" in captured.err


def test_gpu_without_gpu_is_a_clean_error(capsys):
    if svm.device.info()["gpu_usable"]:
        pytest.skip("a GPU is usable here")
    rc = cli.main(["minimize", "--device", "gpu", "-N", "8", "-R", "1"])
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert "gpu" in captured.err.lower()


def test_library_errors_at_setup_are_status_2(monkeypatch, capsys):
    def bad(*args, **kwargs):
        raise ValueError("n_cells is wrong\nand this is a second line")
    monkeypatch.setattr(svm.init, "random_tiling", bad)
    rc = cli.main(["minimize", "-N", "8"])
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert "n_cells is wrong and this is a second line" in captured.err


def test_failures_during_the_run_are_status_1(monkeypatch, capsys):
    def boom(self, **kwargs):
        raise RuntimeError("NaN in replica 0 at step 3")
    monkeypatch.setattr(svm.Simulation, "minimize", boom)
    rc = cli.main(["minimize", "-N", "8", "-R", "1", "--device", "cpu", "--quiet"])
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 1)
    assert "NaN in replica 0" in captured.err


def test_help_and_version(capsys):
    assert cli.main(["--help"]) == 0
    assert "minimize" in capsys.readouterr().out
    assert cli.main(["minimize", "--help"]) == 0
    assert "--p0" in capsys.readouterr().out
    assert cli.main(["--version"]) == 0
    assert svm.__version__ in capsys.readouterr().out


# ------------------------------------------------------------------------------------ info, plugins
def test_info_prints_versions_and_device(capsys):
    assert cli.main(["info"]) == 0
    out = capsys.readouterr().out
    facts = svm.device.info()
    for word in ("spherevm", "python", "numpy", "scipy", "gsd", "trimesh", "cupy", "gpu usable"):
        assert word in out
    line = next(line for line in out.splitlines() if line.startswith("device auto"))
    assert facts["default_device"] in line
    assert svm.__version__ in out and np.__version__ in out


def test_info_json(capsys):
    assert cli.main(["info", "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["spherevm"] == svm.__version__
    assert facts["auto_device"] in ("cpu", "gpu")
    assert isinstance(facts["gpu_usable"], bool)


def test_plugins_lists_builtins_and_entry_points(monkeypatch, capsys):
    assert cli.main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "vertex_model" in out and "fire" in out
    # a plugin package and a broken one on the path: both listed, the broken one does not stop the listing
    monkeypatch.syspath_prepend(str(EXAMPLE))
    monkeypatch.syspath_prepend(str(EXAMPLE / "broken"))
    assert cli.main(["plugins"]) == 0
    lines = capsys.readouterr().out.splitlines()
    lt = next(line for line in lines if line.startswith("line_tension"))
    assert lt.split()[1] == "force" and "spherevm_line_tension:LineTension" in lt
    broken = next(line for line in lines if line.startswith("not_a_plugin"))
    assert "broken" in broken
    sys.modules.pop("spherevm_line_tension", None)
    sys.modules.pop("spherevm_broken_plugin", None)


# ------------------------------------------------------------------------------------ subprocess
def test_python_m_spherevm_info():
    proc = subprocess.run([sys.executable, "-m", "spherevm", "info"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "device auto" in proc.stdout and "numpy" in proc.stdout
    assert "Traceback" not in proc.stderr


def test_python_m_spherevm_bad_arguments():
    proc = subprocess.run([sys.executable, "-m", "spherevm", "minimize", "--cells", "2"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()]
    assert proc.stderr.startswith("spherevm: error: ") and "--cells" in proc.stderr
    assert "Traceback" not in proc.stderr
