"""Bad input caught where it happens (issue 13, items 3, 4, 5, 8, 9; issue 36, items 5, 7, 8, 9)."""
import os
import re
import warnings

import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.writers import GSD

from conftest import to_numpy


# ------------------------------------------------------------------ item 5: FIRE's step guard
def test_fire_exploding_step_is_refused_and_named(device, tmp_path):
    sim = svm.Simulation(device=device)
    sim.state = svm.init.random_tiling(16, replicas=2, seed=1)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = FIRE(dt=1e6)
    sim.operations.writers.append(GSD(1, tmp_path / "x.gsd"))
    before = to_numpy(sim.state.positions).copy()
    with pytest.raises(FloatingPointError, match=r"exploding step at timestep \d+: replica \d+, vertex \d+"):
        sim.minimize(max_steps=200)
    # no frame of a broken state: every frame on disk is a valid, unfolded-by-explosion state
    with svm.gsdio.Reader(tmp_path / "x.gsd") as r:
        for i in range(len(r)):
            r.state(i)
        assert r.state(0).positions.tobytes() == before.tobytes()


def test_fire_guard_leaves_normal_minimisations_alone():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(32, replicas=2, seed=2)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.operations.integrator = FIRE(dt=0.05)
    assert sim.minimize(force_tol=1e-8, max_steps=20000).all_converged


def test_fire_max_step_is_validated():
    with pytest.raises(ValueError, match="max_step"):
        FIRE(max_step=0)


# ------------------------------------------------------------------ item 4: corrupt and foreign files
@pytest.fixture(scope="module")
def good_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("gsd") / "good.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(32, replicas=2, seed=3)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = FIRE(dt=0.05)
    sim.operations.writers.append(GSD(50, path))
    sim.minimize(max_steps=120)
    return path


def _flip_and_read(good, tmp_path, offset):
    data = bytearray(good.read_bytes())
    data[offset] ^= 0xFF
    bad = tmp_path / f"flip{offset}.gsd"
    bad.write_bytes(bytes(data))
    try:
        state = svm.init.from_gsd(bad, frame=-1)
    except ValueError as exc:
        assert str(bad) in str(exc) or repr(str(bad)) in str(exc)
        return "refused"
    except (svm.gsdio.FrameIndexError, FileNotFoundError):  # pragma: no cover - not expected
        raise
    state.validate(orientation=False)      # if it loads, it is a valid State (a changed but sane number)
    return "loaded"


def test_flipped_bytes_are_refused_or_harmless(good_file, tmp_path):
    size = good_file.stat().st_size
    rng = np.random.default_rng(0)
    outcomes = [_flip_and_read(good_file, tmp_path, int(off)) for off in rng.integers(0, size, 150)]
    assert "refused" in outcomes


def _forge(tmp_path, good, edit):
    """A copy of ``good`` with ``edit`` applied to its last frame's chunks; without spherevm/checksum
    (as a file written before checksums, or by a forger), so that the State checks are what reads it."""
    import gsd.fl
    out = tmp_path / "forged.gsd"
    with gsd.fl.open(name=str(good), mode="r") as src:
        names = src.find_matching_chunk_names("")
        n = src.nframes
        chunks = [{name: src.read_chunk(frame=i, name=name) for name in names
                   if src.chunk_exists(frame=i, name=name) and name != svm.gsdio.CHECKSUM} for i in range(n)]
        app, schema, version = src.application, src.schema, src.schema_version
    with gsd.fl.open(name=str(out), mode="w", application=app, schema=schema, schema_version=version) as dst:
        for i, frame in enumerate(chunks):
            if i == n - 1:
                edit(frame)
            for name, arr in frame.items():
                dst.write_chunk(name, arr)
            dst.end_frame()
    return out


@pytest.mark.parametrize("what, edit, message", [
    ("neighbour out of range", lambda f: f.__setitem__("spherevm/vertex_neighbors",
                                                       _set(f["spherevm/vertex_neighbors"], (5, 1), 10 ** 6)),
     "vertex_neighbors of vertex 5"),
    ("cell vertex out of range", lambda f: f.__setitem__("spherevm/cell_vertices",
                                                         _set(f["spherevm/cell_vertices"], (3, 0), 10 ** 6)),
     "cell 3"),
    ("NaN position", lambda f: f.__setitem__("spherevm/position", _set(f["spherevm/position"], (7, 0), np.nan)),
     "vertex 7"),
    ("off the sphere", lambda f: f.__setitem__("spherevm/position", _set(f["spherevm/position"], (9, 2), 0.5)),
     "vertex 9 is off the surface"),
])
def test_forged_frames_are_refused_naming_the_entry(good_file, tmp_path, what, edit, message):
    def full_edit(frame):     # the last frame carries its own topology chunks (else frame 0's are used)
        with svm.gsdio.Reader(good_file) as r:
            for name in svm.gsdio.TOPOLOGY:
                frame.setdefault(svm.gsdio.PREFIX + name, r._chunk(svm.gsdio.PREFIX + name, len(r) - 1))
        edit(frame)
    bad = _forge(tmp_path, good_file, full_edit)
    with pytest.raises(ValueError, match=message) as info:
        svm.init.from_gsd(bad)
    assert "forged.gsd" in str(info.value) and "frame" in str(info.value)
    svm.init.from_gsd(bad, validate=False)          # the opt-out still reads it


def _set(arr, index, value):
    arr = np.array(arr, copy=True)
    arr[index] = value
    return arr


def test_hoomd_file_without_spherevm_chunks(tmp_path):
    import gsd.hoomd
    path = tmp_path / "hoomd.gsd"
    with gsd.hoomd.open(str(path), "w") as f:
        frame = gsd.hoomd.Frame()
        frame.particles.N = 4
        frame.particles.position = np.zeros((4, 3), dtype=np.float32)
        f.append(frame)
    for read in (svm.init.from_gsd, svm.gsdio.read_cell_values):
        with pytest.raises(ValueError, match="without spherevm chunks"):
            read(path)


def test_folded_states_read_unless_orientation_is_asked(tmp_path):
    state = svm.init.random_tiling(32, seed=4)
    cv = state.cell_vertices.copy()
    sim = svm.Simulation(device="cpu")
    sim.state = state
    svm.write_gsd(sim, tmp_path / "ok.gsd")
    svm.init.from_gsd(tmp_path / "ok.gsd", orientation=True)
    assert cv.shape == state.cell_vertices.shape


# ------------------------------------------------------------------ item 8: cells larger than a hemisphere
def squeezed_dodecahedron(factor):
    """The dodecahedron with every polar angle scaled by ``factor`` (the issue's reproduction)."""
    s = svm.init.regular_tiling("dodecahedron")
    R = float(s.radius_np()[0])
    p = s.positions
    theta, phi = factor * np.arccos(p[:, 2] / R), np.arctan2(p[:, 1], p[:, 0])
    s.positions = R * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    return s


@pytest.mark.parametrize("factor", [0.45, 0.55])
def test_a_cell_larger_than_a_hemisphere_is_refused_at_validation(factor, tmp_path):
    s = squeezed_dodecahedron(factor)
    total = s.constraint.cell_areas_np(s).sum()
    assert abs(total - 4 * np.pi * s.radius_np()[0] ** 2) > 1           # the invariant is broken (0, not 4 pi R^2)
    for orientation in (False, True):          # not reported as "clockwise", with or without the sign test
        with pytest.raises(ValueError, match=r"replica 0: the cell areas add up to .* larger than a hemisphere"):
            s.validate(orientation=orientation)
    with pytest.raises(ValueError, match="larger than a hemisphere"):
        svm.State(s.positions, s.cell_vertices, s.cell_sides, s.vertex_neighbors, s.vertex_cells, s.vertex_start,
                  s.cell_start, s.radius)
    sim = svm.Simulation(device="cpu")
    sim.state = svm.State(s.positions, s.cell_vertices, s.cell_sides, s.vertex_neighbors, s.vertex_cells,
                          s.vertex_start, s.cell_start, s.radius, validate=False)
    svm.write_gsd(sim, tmp_path / "big.gsd")
    with pytest.raises(ValueError, match=r"big.gsd.*frame 0.*larger than a hemisphere"):
        svm.init.from_gsd(tmp_path / "big.gsd")


@pytest.mark.parametrize("factor", [0.6, 0.75, 0.9, 1.0])
def test_the_total_area_invariant_holds_for_states_that_pass(factor):
    """Squeezed less, the largest cell stays under a hemisphere: areas add up to 4 pi R^2, no cell is
    clockwise, and the state is valid."""
    s = squeezed_dodecahedron(factor)
    area = s.constraint.cell_areas_np(s)
    R = s.radius_np()[0]
    assert abs(area.sum() - 4 * np.pi * R ** 2) <= 1e-12 * 4 * np.pi * R ** 2
    assert area.min() > 0 and area.max() < 2 * np.pi * R ** 2
    s.validate()


def test_a_cell_over_a_hemisphere_measured_right_is_refused_too():
    """The sum may hold while one cell covers more than half the sphere: refused, it is beyond what
    cell centres and fans are exact for."""
    s = svm.init.regular_tiling("dodecahedron")
    area = s.constraint.cell_areas_np(s)
    big = area.copy()
    big[0], big[1:] = 0.6 * area.sum(), 0.4 * area.sum() / (len(area) - 1)
    with pytest.raises(ValueError, match="cell 0 covers 0.6 of its sphere, more than a hemisphere"):
        svm.simplicity.check_cover(s, big)
    svm.simplicity.check_cover(s, area)


def test_small_random_tilings_have_no_cell_over_a_hemisphere():
    """random_tiling redraws such draws (facet centroids can push a cell past a hemisphere at N = 6)."""
    for seed in range(3):
        s = svm.init.random_tiling(6, replicas=6, seed=seed)
        area = s.constraint.cell_areas_np(s)
        assert area.max() < 2 * np.pi * s.radius_np()[0] ** 2


# ------------------------------------------------------------------ item 3: size guard
def test_huge_tiling_is_refused_before_allocating():
    with pytest.raises(svm.validation.InsufficientMemory, match=r"needs about .* TiB of host memory, but only"):
        svm.init.random_tiling(10 ** 12)


def test_cli_huge_request_is_a_usage_error_at_once(tmp_path):
    import subprocess
    import sys
    import time
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "spherevm", "minimize", "--cells", "1000000000", "--replicas", "1",
                          "-q"], capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=os.getcwd()))
    assert out.returncode == 2, out.stderr
    assert "minimize --cells 1000000000 --replicas 1 needs about" in out.stderr and "is available" in out.stderr
    assert time.monotonic() - start < 60          # refused before anything is built (it was killed at 24 GB)


@pytest.fixture
def half_a_gib(monkeypatch):
    """The machine, as the guards see it, has 0.5 GiB of host memory and 0.25 GiB free on its GPU."""
    monkeypatch.setattr(svm.validation, "available_host_memory", lambda: 2 ** 29)
    monkeypatch.setattr(svm.validation, "available_device_memory", lambda: 2 ** 28)


@pytest.mark.parametrize("make", [lambda: svm.init.random_tiling(200_000, replicas=2),
                                  lambda: svm.init.random_tilings(300_000, [1]),
                                  lambda: svm.init_plane.random_planar_tiling(300_000),
                                  lambda: svm.init_plane.random_planar_tilings(200_000, [1, 2])],
                         ids=["random_tiling", "random_tilings", "random_planar_tiling", "random_planar_tilings"])
def test_initialisers_refuse_what_does_not_fit(half_a_gib, make):
    """States of 500 B per cell plus 2.5 kB per cell of the tiling being built: 0.65 to 0.84 GiB."""
    with pytest.raises(svm.validation.InsufficientMemory, match=r"needs about [0-9.]+ GiB of host memory, but only "
                                                                 r"0.5 GiB is available"):
        make()


@pytest.mark.parametrize("argv, what", [
    (["minimize", "--cells", "150000", "--replicas", "1"], "minimize --cells 150000 --replicas 1"),
    (["dynamics", "--cells", "150000", "--replicas", "1"], "dynamics of 1 replica(s) of 150000 cells"),
])
def test_cli_runs_refuse_what_does_not_fit(half_a_gib, capsys, argv, what):
    """150,000 cells: the State alone (~75 MB) would fit, the CPU run (~0.7 GiB) does not."""
    from spherevm import cli
    assert cli.main([*argv, "--device", "cpu", "-q"]) == 2
    err = capsys.readouterr().err
    assert f"{what} needs about 0.698 GiB of host memory, but only 0.5 GiB is available" in err, err


def test_sweep_refuses_what_does_not_fit_before_making_anything(half_a_gib, tmp_path):
    sweep = svm.sweeps.RigiditySweep(cells=(150_000,), p0=(3.7, 3.8), replicas=1)
    with pytest.raises(svm.validation.InsufficientMemory, match=r"the sweep \(1 worker\(s\), chunks of up to 150000 "
                                                                 r"cells\) needs about .* fewer workers"):
        svm.sweeps.run_sweep(sweep, tmp_path / "sweep", device="cpu", workers=1)
    assert not (tmp_path / "sweep").exists()


def test_gpu_estimates_are_checked_against_free_gpu_memory(half_a_gib):
    """A GPU run needs its State on the host and ~400 B per cell on the GPU (0.25 GiB free here)."""
    svm.validation.check_run_memory("a run", 100_000, 100_000, gpu=True)             # 38 MB on the GPU
    with pytest.raises(svm.validation.InsufficientMemory, match=r"a run needs about 0.373 GiB of GPU memory, but "
                                                                 r"only 0.25 GiB is free"):
        svm.validation.check_run_memory("a run", 1_000_000, 1000, gpu=True)


@pytest.mark.gpu
def test_a_gpu_simulation_refuses_a_state_the_gpu_cannot_hold(monkeypatch):
    monkeypatch.setattr(svm.validation, "available_device_memory", lambda: 1000)
    sim = svm.Simulation(device="gpu")
    with pytest.raises(svm.validation.InsufficientMemory, match="a run of 64 cells on the GPU needs about"):
        sim.state = svm.init.random_tiling(64)


# ------------------------------------------------------------------ item 9: messages at the point of the mistake
@pytest.mark.parametrize("radius", [1e-300, 1e300])
def test_absurd_radius_is_refused_with_the_reason(radius):
    with pytest.raises(ValueError, match="range of float64"):
        svm.init.random_tiling(64, radius=radius)


def test_nan_cell_count_is_refused():
    with pytest.raises(ValueError, match="n_cells"):
        svm.init.random_tiling(float("nan"))


def test_seed_beyond_philox_key_is_refused_at_construction():
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 4294967295\]"):
        svm.Simulation(device="cpu", seed=2 ** 40)


def test_t1_new_edge_shorter_than_the_old_is_refused():
    with pytest.raises(ValueError, match="length_factor must be > 1"):
        svm.plugins.updaters.T1(length_factor=0.5)


def test_gsd_writer_given_a_directory_is_refused_at_construction(tmp_path):
    with pytest.raises(ValueError, match="is a directory; give a file name such as"):
        GSD(filename=tmp_path)


def test_cli_out_in_proc_is_a_usage_error_naming_out():
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-m", "spherevm", "minimize", "--cells", "16", "--replicas", "1", "-q",
                          "--out", "/proc/x.gsd"], capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=os.getcwd()))
    assert out.returncode == 2 and "argument --out" in out.stderr and "Traceback" not in out.stderr, out.stderr


def test_single_p0_sweep_says_why_there_is_no_p0_star(tmp_path, capsys):
    """One p0 value: F(p0) is measured and written, and the table and a note say p0* needs two."""
    from spherevm import cli
    rc = cli.main(["rigidity", "--cells", "16", "--p0", "3.8", "--replicas", "3", "--device", "cpu", "-j", "1",
                   "--no-plots", "--out", str(tmp_path / "one")])
    out, err = capsys.readouterr()
    assert rc == 0
    assert "F at fewer than two p0 values: no p0*" in out and "transition not inside" not in out
    assert "p0* needs F at two or more p0 values" in err and "widen --p0" not in err
    header, row = (tmp_path / "one" / "fraction.csv").read_text().splitlines()
    values = dict(zip(header.split(","), row.split(",")))
    assert values["n_cells"] == "16" and float(values["p0"]) == 3.8 and 0 <= float(values["F"]) <= 1


# ------------------------------------------------------------------ issue 36, item 5: every chunk read is checked
def _fire_t1(seed=0):
    sim = svm.Simulation(device="cpu", seed=seed)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.operations.integrator = FIRE(dt=0.05)
    return sim


@pytest.fixture(scope="module")
def checkpoint_file(tmp_path_factory):
    """A FIRE + T1 minimisation of 2 x 32 cells stopped half way: frames at steps 0, 40, 80, 100."""
    path = tmp_path_factory.mktemp("ck") / "ck.gsd"
    sim = _fire_t1()
    sim.state = svm.init.random_tiling(32, replicas=2, seed=3)
    sim.operations.writers.append(GSD(40, path))
    sim.minimize(max_steps=100, force_tol=1e-12)
    return path


def _replace(name, make):
    def edit(frame):
        frame[name] = make(frame[name])
    return edit


def _drop(name):
    return lambda frame: frame.pop(name)


FIRE_KEY, T1_KEY = "spherevm/op/integrator.FIRE/", "spherevm/op/updaters.0.T1/"
CORRUPT = [
    ("format_version float", _replace("spherevm/format_version", lambda a: a.astype(np.float64)),
     "chunk 'spherevm/format_version': expected uint32, got float64"),
    ("format_version empty", _replace("spherevm/format_version", lambda a: a[:0]),
     "chunk 'spherevm/format_version': expected shape (1,), got (0,)"),
    ("seed float", _replace("spherevm/simulation/seed", lambda a: a.astype(np.float64)),
     "chunk 'spherevm/simulation/seed': expected int64, got float64"),
    ("seed two values", _replace("spherevm/simulation/seed", lambda a: np.array([1, 2])),
     "chunk 'spherevm/simulation/seed': expected shape (1,), got (2,)"),
    ("seed negative", _replace("spherevm/simulation/seed", lambda a: -a - 1),
     "chunk 'spherevm/simulation/seed': expected values >= 0, got -1"),
    ("updated_at text", _replace("spherevm/simulation/updated_at", lambda a: "abc"),
     "chunk 'spherevm/simulation/updated_at': expected a numeric array"),
    ("float32 positions", _replace("spherevm/position", lambda a: a.astype(np.float32)),
     "chunk 'spherevm/position': expected float64, got float32"),
    ("int8 positions", _replace("spherevm/position", lambda a: a.astype(np.int8)),
     "chunk 'spherevm/position': expected float64, got int8"),
    ("radius zero", _replace("spherevm/radius", lambda a: a * 0),
     "chunk 'spherevm/radius': expected values > 0, got 0.0"),
    ("missing T1 field", _drop(T1_KEY + "total_flips"), f"chunk '{T1_KEY}total_flips': missing"),
    ("negative T1 counter", _replace(T1_KEY + "total_refused", lambda a: a - a.max() - 1),
     f"chunk '{T1_KEY}total_refused': expected values >= 0"),
    ("T1 last pass above total", _replace(T1_KEY + "last_flips", lambda a: a + 10 ** 6),
     f"chunk '{T1_KEY}last_flips': expected at most total_flips per replica"),
    ("T1 keys out of order", _replace(T1_KEY + "separated", lambda a: np.array([70, 5], dtype=np.int64)),
     f"chunk '{T1_KEY}separated': expected sorted distinct keys a * 64 + b of cell pairs a < b"),
    ("FIRE alpha above alpha_start", _replace(FIRE_KEY + "alpha", lambda a: a * 0 + 0.5),
     f"chunk '{FIRE_KEY}alpha': expected values <= 0.1, got 0.5"),
    ("FIRE dt zero", _replace(FIRE_KEY + "replica_dt", lambda a: a * 0),
     f"chunk '{FIRE_KEY}replica_dt': expected values > 0, got 0.0"),
    ("FIRE dt above dt_max", _replace(FIRE_KEY + "replica_dt", lambda a: a * 0 + 1e10),
     f"chunk '{FIRE_KEY}replica_dt': expected values <= 0.5, got 10000000000.0"),
    ("FIRE velocity NaN", _replace(FIRE_KEY + "velocities", lambda a: _set(a, (4, 1), np.nan)),
     f"chunk '{FIRE_KEY}velocities': expected finite values, got nan at index (4, 1)"),
    ("FIRE velocities of another State", _replace(FIRE_KEY + "velocities", lambda a: a[1:]),
     f"chunk '{FIRE_KEY}velocities': expected shape (120, 3) for this State, got (119, 3)"),
    ("FIRE counter float", _replace(FIRE_KEY + "n_positive", lambda a: a.astype(np.float64)),
     f"chunk '{FIRE_KEY}n_positive': expected int64, got float64"),
    ("stopped flag flipped", _replace(FIRE_KEY + "stopped", lambda a: 1 - a),
     f"chunk '{FIRE_KEY}reason': expected replica 0's stopped flag, steps, converged flag and reason to agree"),
    ("flag not 0 or 1", _replace(FIRE_KEY + "active", lambda a: a + 2),
     f"chunk '{FIRE_KEY}active': expected values <= 1, got 3"),
    ("reason not UTF-8", _replace(FIRE_KEY + "reason", lambda a: _set(a, 0, 0xFF)),
     f"chunk '{FIRE_KEY}reason': expected UTF-8 text"),
]


@pytest.mark.parametrize("what, edit, message", CORRUPT, ids=[c[0] for c in CORRUPT])
def test_corrupt_chunks_are_refused_naming_file_frame_chunk_and_expectation(checkpoint_file, tmp_path, what, edit,
                                                                           message):
    """Issue 36, item 5: each chunk a restart reads is checked for dtype, shape and range; a failure is
    one ValueError line naming the file, the frame, the chunk and what was expected."""
    bad = _forge(tmp_path, checkpoint_file, edit)
    with pytest.raises(ValueError) as info:
        _fire_t1().create_state_from_gsd(bad)
    text = str(info.value)
    assert message in text and f"{str(bad)!r}, frame 3" in text and "\n" not in text, text


@pytest.mark.parametrize("make, data, message", [
    (lambda n: VertexModel(kA=np.ones(n), kP=1.0, A0=1.0, P0=3.8), lambda n: {"kA": -np.ones(n)},
     "VertexModel: saved field 'kA': expected values >= 0, got -1.0"),
    (lambda n: VertexModel(kA=np.ones(n), kP=1.0, A0=1.0, P0=3.8), lambda n: {"kA": np.ones(n, np.float32)},
     "VertexModel: saved field 'kA': expected float64, got float32"),
    (lambda n: svm.plugins.updaters.RadiusSchedule("constant_area"),
     lambda n: {"area": np.zeros(2), "counts": np.full(2, -1)}, "RadiusSchedule: saved field 'area': expected values > 0"),
])
def test_other_operations_check_what_they_restore(make, data, message):
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(16, replicas=2, seed=1)
    op = make(sim.state.n_cells)
    (sim.operations.forces if isinstance(op, VertexModel) else sim.operations.updaters).append(op)
    with pytest.raises(ValueError, match=re.escape(message)):
        op.restore_state(data(sim.state.n_cells))


def test_planar_box_of_absurd_size_is_refused(tmp_path):
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_planar_tiling(16, seed=1)
    svm.write_gsd(sim, tmp_path / "plane.gsd")
    for side, message in ((1e300, "sqrt(<A>) = inf"), (1e-60, "sqrt(<A>) = 2.5e-61"), (-1.0, "expected values > 0")):
        bad = _forge(tmp_path, tmp_path / "plane.gsd", _replace("spherevm/box", lambda a: a * 0 + side))
        with pytest.raises(ValueError, match=re.escape(message)) as info:
            svm.init.from_gsd(bad, validate=False)
        assert "frame 0, chunk 'spherevm/box': expected" in str(info.value)


def _flip_inside(path, tmp_path, name, frame=-1):
    """A copy of ``path`` with one byte flipped inside chunk ``name`` of ``frame``."""
    import gsd.fl
    with gsd.fl.open(str(path), "r") as f:
        raw = np.ascontiguousarray(f.read_chunk(frame=frame % f.nframes, name=name)).tobytes()
    data = bytearray(path.read_bytes())
    at = data.find(raw)
    assert at > 0 and data.find(raw, at + 1) < 0
    data[at + len(raw) // 2] ^= 0x01            # the lowest bit of a byte in the middle
    out = tmp_path / "flipped.gsd"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("name", [FIRE_KEY + "velocities", "spherevm/position", T1_KEY + "total_flips"])
def test_a_flipped_bit_that_the_schema_cannot_see_is_caught_by_the_checksum(checkpoint_file, tmp_path, name):
    bad = _flip_inside(checkpoint_file, tmp_path, name)
    with pytest.raises(ValueError, match=re.escape(f"frame 3, chunk '{name}': expected the CRC32")):
        _fire_t1().create_state_from_gsd(bad)


def test_random_byte_flips_never_change_a_restart_silently(checkpoint_file, tmp_path):
    """Issue 36, item 5: of byte flips anywhere in a checkpoint file, none restores other state
    without a word: each is refused in one line naming the file, restores exactly the clean state
    (the flip hit what a restart does not read), or warns that the file is damaged."""
    def restore(path):
        sim = _fire_t1()
        sim.create_state_from_gsd(path)
        fire, t1 = sim.operations.integrator, sim.operations.updaters[0]
        arrays = [sim.state.positions, sim.state.cell_vertices, sim.state.vertex_neighbors, sim.state.radius_np(),
                  fire.velocities, fire.replica_dt, fire.alpha, fire.n_positive, fire.stopped, fire.steps,
                  fire.active, np.array([fire.iteration, sim.timestep]), *t1.state_to_save().values()]
        return b"".join(np.ascontiguousarray(a).tobytes() for a in arrays) + str(list(fire.reason)).encode()

    clean = restore(checkpoint_file)
    data = checkpoint_file.read_bytes()
    outcomes = []
    for k, at in enumerate(np.random.default_rng(36).integers(0, len(data), 60)):
        flipped = bytearray(data)
        flipped[at] ^= 0xFF
        path = tmp_path / f"f{k}.gsd"
        path.write_bytes(bytes(flipped))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                got = restore(path)
            except ValueError as exc:
                assert str(path) in str(exc) and "\n" not in str(exc), str(exc)
                outcomes.append("refused")
                continue
        damaged = any(issubclass(w.category, svm.gsdio.DamagedFileWarning) for w in caught)
        assert got == clean or damaged, f"byte {at} changed the restart silently"
        outcomes.append("same" if got == clean else "warned")
    assert "refused" in outcomes and "same" in outcomes


def test_an_index_entry_out_of_frame_order_is_not_trusted(checkpoint_file, tmp_path):
    """A flipped frame number in gsd's index (gsd checks only some entries) would hide a chunk of the
    last frame, which the HOOMD rule then takes from frame 0: the reader stops before that frame."""
    from gsd import pygsd
    data = bytearray(checkpoint_file.read_bytes())
    head = pygsd.gsd_header._make(pygsd.gsd_header_struct.unpack(bytes(data[:256])))
    index = np.frombuffer(bytes(data[head.index_location:head.index_location + 32 * head.index_allocated_entries]),
                          dtype=svm.gsdrecover.ENTRY)
    last = np.flatnonzero(index["frame"] == 3)
    data[head.index_location + 32 * int(last[len(last) // 2])] ^= 0xFF      # frame 3 becomes 252
    bad = tmp_path / "index.gsd"
    bad.write_bytes(bytes(data))
    sim = _fire_t1()
    with pytest.warns(svm.gsdio.DamagedFileWarning, match="reading its 3 complete frame"):
        sim.create_state_from_gsd(bad)
    assert sim.timestep == 80


def test_a_chunk_gsd_cannot_read_is_named(checkpoint_file):
    class Failing:
        def __init__(self, file):
            self.file = file

        def __getattr__(self, name):
            return getattr(self.file, name)

        def read_chunk(self, frame, name):
            raise RuntimeError("Corrupt GSD file")

    with svm.gsdio.Reader(checkpoint_file) as r:
        r.file = Failing(r.file)
        with pytest.raises(ValueError, match=re.escape("frame 3: chunk 'spherevm/format_version' cannot be read "
                                                       "(Corrupt GSD file); the file is damaged")):
            r.state()


# ------------------------------------------------------------------ issue 36, item 7: the GSD writer's path
@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs Linux /proc, where no file can be created")
def test_gsd_writer_into_proc_says_the_path_and_why():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(16, seed=1)
    with pytest.raises(OSError, match=re.escape("GSD writer: cannot open filename '/proc/run.gsd' for writing "
                                                "(No such file or directory)")) as info:
        svm.write_gsd(sim, "/proc/run.gsd")
    assert "\n" not in str(info.value)


# ------------------------------------------------------------------ issue 36, item 7: one line, at the mistake
def _cli(capsys, *argv):
    """``spherevm argv`` in-process with every Python warning an error: (status, stderr)."""
    import warnings
    from spherevm import cli
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rc = cli.main([str(a) for a in argv])
    return rc, capsys.readouterr().err


def _one_error(capsys, argv, message):
    rc, err = _cli(capsys, *argv)
    assert rc == 2 and err == f"spherevm: error: {message}\n", err


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two-replica, 16-cell minimisations written by the CLI: on the sphere (seed 3) and the plane."""
    from spherevm import cli
    folder = tmp_path_factory.mktemp("runs")
    for surface, seed in (("sphere", 3), ("plane", 0)):
        assert cli.main(["minimize", "--cells", "16", "--replicas", "2", "--max-steps", "20", "--seed", str(seed),
                         "--surface", surface, "--device", "cpu", "-q", "--out", str(folder / f"{surface}.gsd")]) == 0
    return folder


@pytest.mark.parametrize("box", [1e-300, 1e300])
def test_planar_box_beyond_float64_is_refused(box):
    with pytest.raises(ValueError, match=rf"^box {re.escape(repr(box))} gives cells of size sqrt\(<A>\) = "
                                         r".*range of float64"):
        svm.init_plane.random_planar_tiling(32, box=box)


@pytest.mark.parametrize("box, message", [
    ((1e-300, 1e300), r"^qhull cannot triangulate 32 points in the box \(1e-300, 1e\+300\) \(QH6019 [^\n]*\); "
                      r"give a box"),
    ((1, 1000), r"^box \(1, 1000\) gave no simple periodic Voronoi tiling of 32 cells in 1000 draws: its narrow side "
                r"is 0.179 cells wide"),
])
def test_planar_box_too_narrow_is_refused_on_one_line(box, message):
    with pytest.raises(ValueError, match=message):
        svm.init_plane.random_planar_tiling(32, box=box)


def test_per_replica_sizes_of_the_wrong_length_are_named():
    p = svm.init.random_planar_tiling(16, replicas=2)
    s = svm.init.random_tiling(16, replicas=2)
    with pytest.raises(ValueError, match=r"^box must be \(Lx, Ly\) or one \(Lx, Ly\) per replica \(2 replicas\), "
                                         r"got shape \(3, 2\)$"):
        svm.State(p.positions, p.cell_vertices, p.cell_sides, p.vertex_neighbors, p.vertex_cells, p.vertex_start,
                  p.cell_start, box=np.full((3, 2), 4.0), constraint=p.constraint)
    with pytest.raises(ValueError, match=r"^radius must be a scalar or one value per replica \(2 replicas\), got "
                                         r"shape \(3,\)$"):
        svm.State(s.positions, s.cell_vertices, s.cell_sides, s.vertex_neighbors, s.vertex_cells, s.vertex_start,
                  s.cell_start, radius=[1.0, 1.0, 1.0])


def _growing(updater, replicas):
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(16, replicas=replicas, seed=5)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.Brownian(dt=0.01, T=0.0)
    sim.operations.updaters.append(updater)
    return sim


@pytest.mark.parametrize("radius, message", [
    (lambda s: [1.0, 1.1, 1.2], r"returned shape \(3,\); it must return a scalar or one radius per replica \(2\)"),
    (lambda s: "big", r"returned 'big'; radii must be positive and finite"),
])
def test_radius_schedule_function_of_the_wrong_length(radius, message):
    sim = _growing(svm.plugins.updaters.RadiusSchedule(radius), replicas=2)
    with pytest.raises(ValueError, match="^RadiusSchedule: the radius function " + message):
        sim.run(2)


def test_division_axis_function_of_the_wrong_shape():
    division = svm.plugins.updaters.Division(rule=lambda s: [0, 1], axis=lambda s, cells: np.ones((len(cells), 2)))
    sim = _growing(division, replicas=1)
    with pytest.raises(ValueError, match=r"^Division: the axis function returned shape \(2, 2\); it must return one "
                                         r"3-D direction per cell to divide, shape \(2, 3\)$"):
        sim.run(2)


def test_check_force_names_a_wrong_force_or_state():
    from spherevm.testing import check_force
    vm, state = VertexModel.dimensionless(kr=1.0, p0=3.8), svm.init.random_tiling(16)
    with pytest.raises(TypeError, match=r"^force must be a spherevm Force \(an object with compute\(state\)\), got "
                                        r"'notaforce'$"):
        check_force("notaforce", state)
    with pytest.raises(TypeError, match="^state must be a spherevm.State, got NoneType$"):
        check_force(vm, None)


def test_render_replica_and_size_are_named(runs, capsys):
    png = runs / "x.png"
    _one_error(capsys, ["render", runs / "sphere.gsd", "--out", png, "--replica", "9"],
               "argument --replica: must be an integer in [0, 1], got 9")
    _one_error(capsys, ["render", runs / "sphere.gsd", "--out", png, "--size", "0", "0"],
               "argument --size: must be positive and finite, got '0'")
    assert not png.exists()


def test_p0_beyond_the_shape_index_limit_is_refused(capsys, tmp_path):
    _one_error(capsys, ["rigidity", "--cells", "16", "--p0", "1e300", "--out", tmp_path / "sweep"],
               "argument --p0: must be finite numbers in (0, 100], got [1e+300]")
    _one_error(capsys, ["minimize", "--p0", "1e300"], "argument --p0: must be a number in [0, 100], got '1e300'")
    _one_error(capsys, ["dynamics", "--p0", "101"], "argument --p0: must be a number in [0, 100], got '101'")


def test_single_p0_sweep_with_plots_is_silent_under_quiet(capsys, tmp_path):
    """matplotlib warned about a legend with no labelled curve (no p0* at one p0 value)."""
    rc, err = _cli(capsys, "rigidity", "--cells", "16", "--p0", "3.8", "--replicas", "2", "--device", "cpu", "-j", "1",
                   "-q", "--out", tmp_path / "one")
    assert rc == 0 and err == ""
    assert (tmp_path / "one" / "fraction.csv").exists()


def test_restart_takes_the_files_seed_and_notes_another(runs, capsys):
    """No raw Python warning: the file's seed by default, another --seed with one note (none with -q)."""
    path = runs / "sphere.gsd"
    argv = ["minimize", "--restart", path, "--max-steps", "5", "--device", "cpu"]
    rc, err = _cli(capsys, *argv, "--out", runs / "restart_a.gsd")
    assert rc == 0 and "note" not in err and "Warning" not in err, err
    assert svm.gsdio.Reader(runs / "restart_a.gsd").checkpoint(-1)["simulation"]["seed"][0] == 3
    rc, err = _cli(capsys, *argv, "--seed", "5", "--out", runs / "restart_b.gsd")
    assert rc == 0 and err.splitlines()[0] == (f"spherevm: note: --seed 5 replaces the seed 3 of the run in {path}: "
                                               "the random numbers from here on differ from that run's"), err
    assert svm.gsdio.Reader(runs / "restart_b.gsd").checkpoint(-1)["simulation"]["seed"][0] == 5
    assert _cli(capsys, *argv, "--seed", "5", "-q") == (0, "")


# ------------------------------------------------------------------ issue 36, item 8: work a user cannot mean
def test_export_refuses_a_mesh_that_cannot_fit(runs, capsys):
    rc, err = _cli(capsys, "export", runs / "sphere.gsd", "--to", runs / "x.ply", "--subdivisions", "100000")
    assert rc == 2 and err.startswith("spherevm: error: a mesh of ") and err.count("\n") == 1, err
    assert "x subdivisions^2 = 100000^2 (" in err and "TiB of host memory, but only" in err and \
        "lower subdivisions" in err
    assert not (runs / "x.ply").exists()


def test_render_refuses_a_picture_past_matplotlibs_limit(runs, capsys, monkeypatch):
    _one_error(capsys, ["render", runs / "sphere.gsd", "--out", runs / "x.png", "--dpi", "100000"],
               "size (6.0, 5.0) inches at dpi 100000 is 600000 x 500000 pixels; matplotlib draws at most 65535 "
               "pixels per side: lower dpi or size")
    monkeypatch.setattr(svm.validation, "available_host_memory", lambda: 2 ** 30)    # 40000^2 x 8 B = 12 GiB
    with pytest.raises(svm.validation.InsufficientMemory, match=r"^a picture of 40000 x 40000 pixels \(size \(100.0, "
                                                                r"100.0\) at dpi 400\) needs about 11.9 GiB"):
        svm.render.render_state(svm.init.random_tiling(16), runs / "x.png", size=(100, 100), dpi=400)


def test_check_force_samples_are_limited():
    from spherevm.testing import MAX_SAMPLES, check_force
    with pytest.raises(ValueError, match=rf"^samples must be an integer in \[1, {MAX_SAMPLES}\], got 1000000$"):
        check_force(VertexModel.dimensionless(kr=1.0, p0=3.8), svm.init.random_tiling(16), samples=10 ** 6)


# ------------------------------------------------------------------ issue 36, item 9: flags ignored or doubled
@pytest.mark.parametrize("flags, message", [
    (["--force", "bending:B=1,B=2"],
     "argument --force: force 'bending': parameter B is given twice in 'bending:B=1,B=2'; give it once"),
    (["--bending", "1", "--force", "bending:B=2"],
     "argument --bending: --bending 1 and --force bending add the same force twice; give each force once"),
    (["--force", "bending:B=1", "--force", "bending:B=2"],
     "argument --force: --force bending and --force bending add the same force twice; give each force once"),
])
def test_a_force_given_twice_is_refused(capsys, flags, message):
    _one_error(capsys, ["minimize", "--cells", "16", "--replicas", "1", "--max-steps", "5", "--device", "cpu", "-q",
                        *flags], message)


@pytest.mark.parametrize("command", ["minimize", "dynamics"])
@pytest.mark.parametrize("file, flags, message", [
    ("plane.gsd", ["--surface", "sphere"], "argument --surface: sphere, but --restart '{}' holds a tissue on the "
                                           "plane"),
    ("sphere.gsd", ["--surface", "plane"], "argument --surface: plane, but --restart '{}' holds a tissue on the "
                                           "sphere"),
    ("sphere.gsd", ["--cells", "32"], "argument --cells: 32, but --restart '{}' holds 16 cells per replica"),
    ("sphere.gsd", ["--replicas", "3"], "argument --replicas: 3, but --restart '{}' holds 2 replica(s)"),
])
def test_restart_refuses_a_contradicting_flag(runs, capsys, command, file, flags, message):
    path = runs / file
    _one_error(capsys, [command, "--restart", path, "--device", "cpu", "-q", *flags],
               message.format(path) + f"; leave {flags[0]} out with --restart")


def test_restart_takes_a_flag_that_agrees(runs, capsys):
    rc, err = _cli(capsys, "dynamics", "--restart", runs / "plane.gsd", "--surface", "plane", "--cells", "16",
                   "--replicas", "2", "--steps", "5", "--device", "cpu", "-q")
    assert rc == 0 and err == "", err
