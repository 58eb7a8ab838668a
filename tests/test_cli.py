"""The ``spherevm`` command line: in-process through ``spherevm.cli.main`` and once as a subprocess."""
from __future__ import annotations

import ast
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import spherevm as svm
from spherevm import cli, sweeps
from spherevm.cli import rigidity as rigidity_cli

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
    # off a terminal (here, captured) no progress bar: the start line and the summary only
    # (tests/test_progress.py checks the bar on a terminal)
    assert len(captured.err.splitlines()) == 2 and "replicas done" not in captured.err
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
    # the printed numbers are those of the last frame written, per replica, in the printed columns:
    # energy per cell and max|F| of the default model (kr = 1, p0 = 3.8), and the mean shape index
    from spherevm.plugins.forces import VertexModel
    res = VertexModel.dimensionless(kr=1.0, p0=3.8).compute(state)
    energy = np.asarray(res.energy) / 16
    fmag = np.linalg.norm(np.asarray(res.forces), axis=1)
    fmax = np.array([fmag[state.vertex_start[r]:state.vertex_start[r + 1]].max() for r in range(3)])
    shape = np.asarray(svm.shapes.mean_shape_index(state))
    printed = np.array([[float(r[1]), float(r[2]), float(r[3])] for r in rows])
    assert np.all(energy > 0)                             # p0 = 3.8 at N = 16: rigid, E > 0
    assert printed[:, 0] == pytest.approx(energy, rel=1e-5)
    assert printed[:, 1] == pytest.approx(shape, abs=2e-6)
    assert printed[:, 2] == pytest.approx(fmax, rel=2e-3)


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
    monkeypatch.setattr(svm.init, "tilings_on", bad)
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


# ------------------------------------------------------------------------------------ rigidity
def _rigidity_args(*argv):
    return cli.build_parser().parse_args(["rigidity", *argv])


def test_rigidity_runs_a_tiny_sweep_and_writes_tables(tmp_path, capsys):
    out = tmp_path / "cli"
    args = _rigidity_args("--cells", "16", "--p0", "3.3", "4.2", "--replicas", "2", "--device", "cpu",
                          "--workers", "1", "--out", str(out))
    assert args.func is rigidity_cli.run
    assert args.func(args) == 0
    captured = capsys.readouterr()
    assert "pentagon" in captured.out and "16" in captured.out
    assert "chunks 1/1" not in captured.err        # no progress bar off a terminal (tests/test_progress.py)
    names = set(os.listdir(out))
    assert {"manifest.json", "chunks", "replicas.csv", "fraction.csv", "p0star.csv", "p0star_density.csv"} <= names
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        pass
    else:
        assert {"fraction.png", "p0star_distribution.png", "p0star_vs_N.png"} <= names
        assert "critical_perimeter.png" not in names   # sqrt(<A>) p0*(N): nothing p0star_vs_N.png lacks
    lines = (out / "fraction.csv").read_text().splitlines()
    assert lines[0].startswith("n_cells,p0,n_replicas,n_zero,n_rigid,n_unconverged")
    assert lines[1].startswith("16,3.3,2,0,2,0") and lines[2].startswith("16,4.2,2,2,0,0")
    # a mismatching rerun fails before any work
    args = _rigidity_args("--cells", "16", "--p0", "3.3", "4.2", "--replicas", "3", "--device", "cpu",
                          "--out", str(out))
    with pytest.raises(ValueError, match="different parameters"):
        args.func(args)
    rc = cli.main(["rigidity", "--cells", "16", "--p0", "3.3", "4.2", "--replicas", "3", "--device", "cpu",
                   "--out", str(out)])
    _assert_one_line_error(capsys.readouterr(), rc, 2)


def test_rigidity_defaults_are_the_small_sweep():
    args = _rigidity_args()
    assert args.cells == [16, 32] and args.replicas == 12
    assert sweeps.parse_p0_grid(args.p0) == pytest.approx(np.round(np.arange(3.5, 4.0001, 0.025), 10))
    assert args.kr == 0.0 and args.device == "auto"
    sweep = rigidity_cli.sweep_from_args(args)
    assert sweep == sweeps.RigiditySweep(cells=[16, 32], p0=sweeps.parse_p0_grid(["3.5:4.0:0.025"]), replicas=12)
    ref = rigidity_cli.sweep_from_args(_rigidity_args("--t1-reference"))
    assert ref.t1_threshold == 0.1 and ref.t1_length_factor == 2.0
    for bad in (["--p0", "3.9", "3.8"], ["--p0", "3.6:3.5:0.1"]):
        with pytest.raises(ValueError, match="p0"):
            rigidity_cli.sweep_from_args(_rigidity_args(*bad))


@pytest.mark.parametrize("argv, message", [
    (["rigidity", "--cells", "16", "2"], "argument --cells/-N: must be an integer >= 4, got '2'"),
    (["rigidity", "--replicas", "0"], "argument --replicas/-R: must be an integer >= 1, got '0'"),
    (["rigidity", "--seed", "-1"], "argument --seed: must be a non-negative integer, got '-1'"),
    (["rigidity", "--zero-tol", "0"], "argument --zero-tol: must be positive and finite, got '0'"),
    (["rigidity", "--workers", "x"], "argument --workers/-j: must be an integer >= 1, got 'x'"),
    (["dynamics", "--T", "-1"], "argument --T/-T: must be a finite number >= 0, got '-1'"),
])
def test_bad_values_name_the_flag_and_the_range(argv, message, capsys):
    rc = cli.main(argv)
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert captured.err.strip() == f"spherevm: error: {message}"


def _imports(path, root):
    """Absolute names of the modules a file imports (relative imports resolved)."""
    package = ".".join(("spherevm",) + path.relative_to(root).parent.parts)
    names = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            module = ".".join(p for p in (base, node.module) if p)
            names += [module] + [f"{module}.{alias.name}" for alias in node.names]
    return names


def test_the_library_does_not_import_the_command_line():
    """Layers point down: argparse and spherevm.cli are imported only by spherevm/cli/ (and __main__)."""
    root = pathlib.Path(svm.__file__).parent
    for path in root.rglob("*.py"):
        if root / "cli" in path.parents or path == root / "__main__.py":
            continue
        for name in _imports(path, root):
            assert name != "argparse" and not (name + ".").startswith("spherevm.cli."), (path, name)


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


# ------------------------------------------------------------------------------------ small things (issue 35.9)
@pytest.mark.parametrize("argv", [["minimize", "--cell", "16"], ["dynamics", "--step", "10"],
                                  ["rigidity", "--cell", "16"], ["--deb", "info"]])
def test_no_option_is_taken_from_a_prefix(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)          # were --cell taken for --cells, the sweep would land here
    rc = cli.main(argv)
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert f"unrecognized arguments: {argv[-2] if argv[0] != '--deb' else '--deb'}" in captured.err


def _parsers(parser):
    yield parser
    for action in parser._actions:
        for sub in (getattr(action, "choices", None) or {}).values() if hasattr(action, "add_parser") else ():
            yield from _parsers(sub)


def test_every_parser_refuses_abbreviations():
    """The command's parsers, and every argparse parser of the examples and benchmarks."""
    parsers = list(_parsers(cli.build_parser()))
    assert len(parsers) == 1 + len(cli.COMMAND_NAMES) and not any(p.allow_abbrev for p in parsers)
    root = pathlib.Path(__file__).resolve().parent.parent
    scripts = sorted([*root.glob("examples/*.py"), *root.glob("benchmarks/*.py")])
    calls = [(path.name, node) for path in scripts
             for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.Call)
             and getattr(node.func, "attr", getattr(node.func, "id", None)) == "ArgumentParser"]
    assert len(calls) >= 18
    for name, node in calls:
        assert any(k.arg == "allow_abbrev" and k.value.value is False for k in node.keywords), name


def test_a_misspelt_force_parameter_is_answered_with_the_nearest(capsys):
    rc = cli.main(["minimize", "-N", "8", "--force", "bending:b=1"])
    captured = capsys.readouterr()
    _assert_one_line_error(captured, rc, 2)
    assert "force 'bending' has no parameter 'b' (did you mean 'B'?); its parameters: B=0.0" in captured.err


class _CtrlC:
    """A progress display that raises KeyboardInterrupt at its ``at``-th production update."""

    def __init__(self, *args, at=2, **kwargs):
        self.calls, self.at = 0, at

    def __call__(self, *args):
        if args[0] != "relax" and args[0] != "equilibrate":
            self.calls += 1
            if self.calls == self.at:
                raise KeyboardInterrupt

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def close(self):
        pass


@pytest.mark.parametrize("command,extra", [
    ("minimize", ["--write-every", "10", "--check-every", "10", "--p0", "3.9", "--energy-tol", "0"]),
    ("dynamics", ["--relax", "20", "--equilibrate", "0", "--steps", "400"]),
])
def test_ctrl_c_says_how_to_continue_with_restart(command, extra, tmp_path, monkeypatch, capsys):
    from spherevm.cli import dynamics, minimize
    from spherevm.cli.arguments import gsd_frames
    monkeypatch.setattr(minimize, "MinimizeBar", _CtrlC)
    monkeypatch.setattr(dynamics, "StageBars", _CtrlC)
    out = tmp_path / "run.gsd"
    base = [command, "-N", "16", "-R", "1", "--device", "cpu", *extra]
    assert cli.main([*base, "--out", str(out)]) == 130
    err = capsys.readouterr().err.strip().splitlines()[-1]
    frames, step = gsd_frames(out)
    assert frames >= 1 and step > 0
    assert err == (f"spherevm: interrupted; {out} holds {frames} frame{'s' * (frames != 1)}, the last at step {step}: "
                   f"continue from it with 'spherevm {command} --restart {out}' and the other options as before")
    monkeypatch.undo()
    assert cli.main([*base, "--restart", str(out), "--quiet"]) == 0      # what the line says works
    capsys.readouterr()
    monkeypatch.setattr(minimize, "MinimizeBar", _CtrlC)
    monkeypatch.setattr(dynamics, "StageBars", _CtrlC)
    assert cli.main(base) == 130                                          # nothing written: the plain line
    assert capsys.readouterr().err.strip().splitlines()[-1] == "spherevm: interrupted"
