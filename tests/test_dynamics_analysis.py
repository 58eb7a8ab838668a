"""Dynamics analysis: centroids, rigid-rotation removal, MSD, Q_s, F_s, tau_alpha, log sampling, Recorder."""
import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import j0

import spherevm as svm
from spherevm.analysis import (NoRelaxationWarning, Trajectory, msd, remove_rigid_rotation,
                               self_intermediate_scattering, self_overlap, tau_alpha)
from spherevm.plugins.writers import Recorder
from spherevm.plugins.writers.recorder import log_spaced_times
from spherevm.shapes import cell_centroids
from spherevm.trigger import OnTimesteps


# ------------------------------------------------------------------------------------ helpers
def sphere_points(rng, n, radius):
    x = rng.normal(size=(n, 3))
    return radius * x / np.linalg.norm(x, axis=1)[:, None]


def ensemble(rng, n_cells, n_replicas, radius=None):
    """Random cell positions for n_replicas tissues of n_cells, default radius sqrt(N / 4 pi) (<A> = 1)."""
    R = math.sqrt(n_cells / (4 * math.pi)) if radius is None else radius
    pts = np.concatenate([sphere_points(rng, n_cells, R) for _ in range(n_replicas)])
    rep = np.repeat(np.arange(n_replicas), n_cells)
    return pts, rep, np.full(n_replicas, R)


def random_tangent(rng, x):
    v = rng.normal(size=x.shape)
    n = x / np.linalg.norm(x, axis=-1)[..., None]
    v -= (v * n).sum(axis=-1)[..., None] * n
    return v / np.linalg.norm(v, axis=-1)[..., None]


def geodesic_step(x, direction, s):
    """The point at arc length s from x along the unit tangent direction."""
    R = np.linalg.norm(x, axis=-1)[..., None]
    phi = np.asarray(s)[..., None] / R
    return np.cos(phi) * x + R * np.sin(phi) * direction


# ------------------------------------------------------------------------------------ centroids
def test_centroids_on_sphere_and_methods_agree_on_symmetric_cells():
    state = svm.init.random_tiling(64, replicas=2, seed=3)
    for method in ("area", "vertex"):
        c = cell_centroids(state, method=method)
        assert c.shape == (state.n_cells, 3)
        np.testing.assert_allclose(np.linalg.norm(c, axis=1), state.radius_np()[state.cell_replica_np()],
                                   rtol=1e-13)
    apex = state.constraint.cell_centers(state)
    radius = state.radius_np()[state.cell_replica_np()][:, None]
    np.testing.assert_allclose(cell_centroids(state, "vertex"), apex * radius, atol=1e-12)
    # random cells: the two definitions differ, but by much less than a cell size
    diff = np.linalg.norm(cell_centroids(state, "area") - cell_centroids(state, "vertex"), axis=1)
    assert diff.max() > 1e-4 and diff.max() < 0.3
    # a regular tiling: both give the face centres
    try:
        dod = svm.init.regular_tiling("dodecahedron")
    except ImportError:   # an optional dependency of the regular tilings
        dod = None
    if dod is not None:
        np.testing.assert_allclose(cell_centroids(dod, "area"), cell_centroids(dod, "vertex"), atol=1e-12)
    with pytest.raises(ValueError, match="method"):
        cell_centroids(state, method="mass")


def test_area_centroid_matches_numerical_integration():
    """The closed form for the integral of the normal over a spherical polygon against a fine quadrature."""
    state = svm.init.random_tiling(40, seed=5)
    R = state.radius_np()[0]
    c = cell_centroids(state, "area") / R
    cv, sides = state.cell_vertices, state.cell_sides
    unit = state.positions / np.linalg.norm(state.positions, axis=1)[:, None]
    apex = state.constraint.cell_centers(state)
    m = 60  # subdivisions of each fan triangle
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    up = i + j <= m - 1                # triangles (i, j), (i+1, j), (i, j+1)
    dn = i + j <= m - 2                # triangles (i+1, j), (i+1, j+1), (i, j+1): same orientation
    iu, ju, idn, jdn = i[up], j[up], i[dn], j[dn]
    for cell in range(6):
        acc = np.zeros(3)
        loop = cv[cell, :sides[cell]]
        for k in range(sides[cell]):
            a, b, cc = apex[cell], unit[loop[k]], unit[loop[(k + 1) % sides[cell]]]

            def point(ii, jj):
                u, v = ii[:, None] / m, jj[:, None] / m
                p = (1 - u - v) * a + u * b + v * cc
                return p / np.linalg.norm(p, axis=1)[:, None]
            tris = ((point(iu, ju), point(iu + 1, ju), point(iu, ju + 1)),
                    (point(idn + 1, jdn), point(idn + 1, jdn + 1), point(idn, jdn + 1)))
            for p, q, r in tris:
                num = (p * np.cross(q, r)).sum(axis=1)
                den = 1 + (p * q).sum(axis=1) + (q * r).sum(axis=1) + (r * p).sum(axis=1)
                omega = 2 * np.arctan2(num, den)
                mid = p + q + r
                acc += (omega[:, None] * mid / np.linalg.norm(mid, axis=1)[:, None]).sum(axis=0)
        direction = acc / np.linalg.norm(acc)
        assert np.linalg.norm(direction - c[cell]) < 1e-5   # the vertex centroid is 5e-5 to 0.14 away


# ------------------------------------------------------------------------------------ rotation removal
def test_remove_rotation_recovers_random_rotation_per_replica():
    rng = np.random.default_rng(1)
    ref, rep, _ = ensemble(rng, 50, 4)
    rots = Rotation.random(4, random_state=2).as_matrix()
    cur = np.einsum("cab,cb->ca", rots[rep], ref)
    back, Q = remove_rigid_rotation(ref, cur, rep, return_rotation=True)
    np.testing.assert_allclose(back, ref, atol=1e-12)
    np.testing.assert_allclose(Q, np.swapaxes(rots, 1, 2), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(Q), 1.0, atol=1e-12)


def test_remove_rotation_replicas_independent_and_batched():
    rng = np.random.default_rng(2)
    ref, rep, _ = ensemble(rng, 40, 3)
    rots = Rotation.random(3, random_state=4).as_matrix()
    cur = np.einsum("cab,cb->ca", rots[rep], ref)
    noisy = cur.copy()
    noisy[rep == 0] += 0.3 * rng.normal(size=(40, 3))      # replica 0: noise, no exact answer
    noisy[rep == 2] = sphere_points(rng, 40, 1.0)          # replica 2: unrelated points
    back = remove_rigid_rotation(ref, noisy, rep)
    np.testing.assert_allclose(back[rep == 1], ref[rep == 1], atol=1e-12)  # untouched by the others
    assert np.abs(back[rep == 0] - ref[rep == 0]).max() > 1e-3
    # leading time axis, shuffled cell order: same answers
    perm = rng.permutation(len(rep))
    stack = np.stack([cur, noisy])[:, perm]
    out = remove_rigid_rotation(ref[perm], stack, rep[perm])
    np.testing.assert_allclose(out[0], ref[perm], atol=1e-12)
    np.testing.assert_allclose(out[1], back[perm], atol=1e-12)


def test_remove_rotation_is_proper_for_a_mirror_image():
    rng = np.random.default_rng(3)
    ref, rep, _ = ensemble(rng, 30, 1)
    mirrored = ref * np.array([1.0, 1.0, -1.0])
    _, Q = remove_rigid_rotation(ref, mirrored, rep, return_rotation=True)
    assert np.linalg.det(Q[0]) == pytest.approx(1.0, abs=1e-12)


# ------------------------------------------------------------------------------------ MSD and Q_s
def rotating_trajectory(rng, n_cells=60, n_replicas=3, n_frames=8):
    ref, rep, radius = ensemble(rng, n_cells, n_replicas)
    frames = [ref]
    for k in range(1, n_frames):
        rots = Rotation.random(n_replicas, random_state=100 + k).as_matrix()
        frames.append(np.einsum("cab,cb->ca", rots[rep], ref))
    return Trajectory(np.arange(n_frames), np.stack(frames), rep, radius)


def test_rigid_rotation_gives_no_msd_and_full_overlap_after_removal():
    traj = rotating_trajectory(np.random.default_rng(4))
    for geodesic in (False, True):
        m = msd(traj, geodesic=geodesic)
        assert np.abs(m.value).max() < 1e-20
        assert np.all(self_overlap(traj, geodesic=geodesic).value == 1.0)
        np.testing.assert_allclose(self_intermediate_scattering(traj, geodesic=geodesic).value, 1.0, atol=1e-12)
    raw = msd(traj, remove_rotation=False)
    assert raw.value[0] == 0 and np.all(raw.value[1:] > 0.1)
    assert np.all(self_overlap(traj, remove_rotation=False).value[1:] < 0.9)
    for origins in ("all", [0, 3, 5]):
        assert np.abs(msd(traj, origins=origins).value).max() < 1e-20


def test_known_displacements_give_exact_msd_and_overlap_step():
    rng = np.random.default_rng(5)
    n = 32
    x0, rep, radius = ensemble(rng, n, 2)
    R = radius[0]
    s = np.where(np.arange(2 * n) % 2 == 0, 0.3, 0.7)          # arc lengths, half of the cells each
    x1 = geodesic_step(x0, random_tangent(rng, x0), s)
    traj = Trajectory([0.0, 5.0], np.stack([x0, x1]), rep, radius)
    chord = 2 * R * np.sin(s / (2 * R))
    m = msd(traj, remove_rotation=False)
    np.testing.assert_allclose(m.lag, [0.0, 5.0])
    np.testing.assert_allclose(m.value, [0.0, np.mean(chord ** 2)], rtol=1e-13, atol=0)
    np.testing.assert_allclose(msd(traj, remove_rotation=False, geodesic=True).value, [0.0, np.mean(s ** 2)],
                               rtol=1e-12)
    assert msd(traj, remove_rotation=False, geodesic=True).per_replica.shape == (2, 2)
    for b, expected in ((0.29, 0.0), (0.31, 0.5), (0.5, 0.5), (0.69, 0.5), (0.71, 1.0)):
        assert self_overlap(traj, b=b, remove_rotation=False).value[1] == expected
    # between chord and arc: the chord window keeps the cells, the geodesic one does not
    s2 = np.full(2 * n, 0.5005)
    x2 = geodesic_step(x0, random_tangent(rng, x0), s2)
    traj2 = Trajectory([0, 1], np.stack([x0, x2]), rep, radius)
    assert self_overlap(traj2, remove_rotation=False).value[1] == 1.0
    assert self_overlap(traj2, remove_rotation=False, geodesic=True).value[1] == 0.0
    # lengths are in units of sqrt(<A>): doubling the sphere and the displacements changes nothing
    big = Trajectory([0.0, 5.0], 2 * np.stack([x0, x1]), rep, 2 * radius)
    np.testing.assert_allclose(msd(big, remove_rotation=False).value, m.value, rtol=1e-13)
    np.testing.assert_allclose(msd(big, remove_rotation=False, scaled=False).value, 4 * m.value, rtol=1e-13)


def test_all_origins_average_over_equal_lags():
    rng = np.random.default_rng(6)
    x0, rep, radius = ensemble(rng, 30, 1)
    axes = random_tangent(rng, x0)
    omega = np.linspace(0.02, 0.2, len(x0))   # each cell turns at its own rate on its own great circle
    T = 6
    frames = np.stack([geodesic_step(x0, axes, omega * k) for k in range(T)])
    traj = Trajectory(np.arange(T) * 0.5, frames, rep, radius)
    first = msd(traj, remove_rotation=False, geodesic=True)
    allo = msd(traj, remove_rotation=False, geodesic=True, origins="all")
    np.testing.assert_allclose(allo.lag, first.lag, atol=1e-12)
    np.testing.assert_allclose(allo.value, first.value, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(allo.count, T - np.arange(T))
    np.testing.assert_allclose(first.value, np.mean((omega[None] * np.arange(T)[:, None]) ** 2, axis=1),
                               rtol=1e-12, atol=1e-15)


# ------------------------------------------------------------------------------------ F_s
def test_fs_gaussian_tangent_displacements():
    """2D Gaussian steps in the tangent plane: F_s(q) = exp(-q^2 sigma^2 / 2) (2D average)."""
    rng = np.random.default_rng(7)
    n = 20000
    x0, rep, radius = ensemble(rng, n, 1)
    sigma = 0.15
    R = radius[0]
    n0 = x0 / R
    e1 = random_tangent(rng, x0)
    e2 = np.cross(n0, e1)
    g = sigma * rng.normal(size=(n, 2))
    step = g[:, :1] * e1 + g[:, 1:] * e2
    s = np.linalg.norm(step, axis=1)
    x1 = geodesic_step(x0, step / s[:, None], s)
    traj = Trajectory([0, 1], np.stack([x0, x1]), rep, radius)
    for q in (np.pi, 2 * np.pi):
        fs = self_intermediate_scattering(traj, q=q, remove_rotation=False, geodesic=True)
        assert fs.value[0] == 1.0
        assert fs.value[1] == pytest.approx(np.exp(-q * q * sigma * sigma / 2), abs=0.01)
        np.testing.assert_allclose(fs.value[1], np.mean(j0(q * s)), rtol=1e-12)
    # the 3D average is the mean of sin(qd)/(qd) and differs from the 2D one
    f3 = self_intermediate_scattering(traj, remove_rotation=False, geodesic=True, average="3d").value[1]
    x = 2 * np.pi * s
    np.testing.assert_allclose(f3, np.mean(np.sin(x) / x), rtol=1e-12)
    assert f3 > self_intermediate_scattering(traj, remove_rotation=False, geodesic=True).value[1] + 0.05


def test_fs_averages_match_explicit_direction_averages():
    rng = np.random.default_rng(8)
    n = 50
    x0, rep, radius = ensemble(rng, n, 1, radius=50.0)   # large sphere: steps almost tangent
    s = rng.uniform(0.05, 0.6, n)
    t = random_tangent(rng, x0)
    x1 = geodesic_step(x0, t, s)
    dr = x1 - x0
    unit_len = math.sqrt(4 * math.pi * 50.0 ** 2 / n)
    q = 2 * np.pi / unit_len                       # F_s uses q in units of 1/sqrt(<A>)
    traj = Trajectory([0, 1], np.stack([x0, x1]), rep, radius)
    # explicit average of cos(q.dr) over q in the tangent plane at r(0)
    phi = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    n0 = x0 / 50.0
    e2 = np.cross(n0, t)
    qd = q * (np.cos(phi)[:, None] * (dr * t).sum(1) + np.sin(phi)[:, None] * (dr * e2).sum(1))
    explicit2d = np.cos(qd).mean()
    got2d = self_intermediate_scattering(traj, q=2 * np.pi, remove_rotation=False).value[1]
    assert got2d == pytest.approx(explicit2d, abs=1e-5)
    # explicit average over all directions of q (Fibonacci sphere)
    k = np.arange(20000) + 0.5
    z = 1 - 2 * k / len(k)
    ang = np.pi * (1 + 5 ** 0.5) * k
    dirs = np.stack([np.sqrt(1 - z * z) * np.cos(ang), np.sqrt(1 - z * z) * np.sin(ang), z], axis=1)
    explicit3d = np.cos(q * dirs @ dr.T).mean()
    got3d = self_intermediate_scattering(traj, q=2 * np.pi, remove_rotation=False, average="3d").value[1]
    assert got3d == pytest.approx(explicit3d, abs=1e-4)
    with pytest.raises(ValueError, match="average"):
        self_intermediate_scattering(traj, average="1d")


# ------------------------------------------------------------------------------------ tau_alpha
@pytest.mark.parametrize("tau", [3.7, 42.0, 777.0])
def test_tau_alpha_of_exponential(tau):
    t = np.concatenate([[0], log_spaced_times(100_000, 10)]).astype(float)
    t = np.unique(t)
    q = np.exp(-t / tau)
    assert tau_alpha(t, q) == pytest.approx(tau, rel=3e-3)
    assert tau_alpha(t, q, interpolation="linear") == pytest.approx(tau, rel=0.05)
    # log interpolation is the better one for log-spaced samples
    assert abs(tau_alpha(t, q) - tau) < abs(tau_alpha(t, q, interpolation="linear") - tau)
    dense = np.linspace(0, 10 * tau, 20001)
    assert tau_alpha(dense, np.exp(-dense / tau)) == pytest.approx(tau, rel=1e-6)
    # per-curve columns, and from a TimeCorrelation
    two = np.stack([np.exp(-t / tau), np.exp(-t / (2 * tau))], axis=1)
    np.testing.assert_allclose(tau_alpha(t, two), [tau, 2 * tau], rtol=3e-3)


def test_tau_alpha_nan_with_warning():
    t = np.arange(1.0, 11.0)
    with pytest.warns(NoRelaxationWarning, match="never fell"):
        assert math.isnan(tau_alpha(t, np.full(10, 0.9)))
    with pytest.warns(NoRelaxationWarning, match="first sample"):
        assert math.isnan(tau_alpha(t, np.full(10, 0.1)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert math.isnan(tau_alpha(t, np.full(10, 0.9), warn=False))
    with pytest.warns(NoRelaxationWarning):
        out = tau_alpha(t, np.stack([np.full(10, 0.9), np.linspace(1, 0, 10)], axis=1))
    assert math.isnan(out[0]) and np.isfinite(out[1])


def test_tau_alpha_from_self_overlap():
    """Cells leaving one by one at known times: Q_s crosses 1/e where the fraction left passes 1 - 1/e."""
    rng = np.random.default_rng(9)
    n = 100
    x0, rep, radius = ensemble(rng, n, 1)
    leave = np.arange(1, n + 1) * 10.0      # cell i jumps by 1.0 at time leave[i]
    times = np.arange(0, 1011, 10.0)
    d = random_tangent(rng, x0)
    frames = np.stack([geodesic_step(x0, d, np.where(leave <= tt, 1.0, 0.0)) for tt in times])
    traj = Trajectory(times, frames, rep, radius)
    qs = self_overlap(traj, remove_rotation=False)
    np.testing.assert_allclose(qs.value, np.clip(1 - times / 1000.0, 0, 1), atol=1e-12)
    assert qs.tau_alpha(interpolation="linear") == pytest.approx(1000 * (1 - 1 / math.e), rel=1e-9)


# ------------------------------------------------------------------------------------ sampling
def test_log_spaced_times_properties():
    t = log_spaced_times(10_000, points_per_decade=10)
    assert t.dtype.kind == "i"
    assert t[0] == 0 and t[1] == 1 and t[-1] == 10_000
    assert np.all(np.diff(t) > 0)
    # about 10 per decade above the integer-crowded start
    assert np.sum((t >= 1000) & (t < 10_000)) == 10
    ratios = t[t >= 100][1:] / t[t >= 100][:-1]
    np.testing.assert_allclose(ratios, 10 ** 0.1, rtol=0.02)
    t2 = log_spaced_times(777, points_per_decade=4, t_min=5, include_zero=False)
    assert t2[0] == 5 and t2[-1] == 777 and np.all(np.diff(t2) > 0)
    assert log_spaced_times(1).tolist() == [0, 1]
    for bad in (dict(t_max=0), dict(t_max=10, t_min=20), dict(t_max=10, points_per_decade=0)):
        with pytest.raises(ValueError):
            log_spaced_times(**bad)


def test_on_timesteps_trigger():
    trig = OnTimesteps([5, 1, 1, 100])
    assert [s for s in range(200) if trig(s)] == [1, 5, 100]
    assert isinstance(trig, svm.trigger.Trigger)
    assert trig.last == 100
    assert (trig | svm.trigger.On(7))(7)
    for bad in ([], [-1], [1.5]):
        with pytest.raises(ValueError):
            OnTimesteps(bad)


# ------------------------------------------------------------------------------------ live simulation
def make_sim():
    sim = svm.Simulation(device="cpu", seed=1)
    sim.state = svm.init.random_tiling(32, replicas=2, seed=2)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    return sim


def test_recorder_on_live_simulation(tmp_path, monkeypatch):
    gsd = pytest.importorskip("gsd.hoomd")
    gsd_fl = pytest.importorskip("gsd.fl")
    sim = make_sim()
    wanted = log_spaced_times(300, points_per_decade=5)
    rec = Recorder(OnTimesteps(wanted), csv=tmp_path / "cells.csv")
    sim.operations.writers.append(rec)
    writer = svm.plugins.writers.GSD(OnTimesteps(wanted), tmp_path / "run.gsd", mode="wb")
    sim.operations.writers.append(writer)
    sim.run(300)
    writer.close()
    rec.close()
    np.testing.assert_array_equal(rec.timesteps, wanted)
    traj = Trajectory.from_recording(rec)
    assert traj.centroids.shape == (len(wanted), sim.state.n_cells, 3)
    np.testing.assert_array_equal(traj.times, wanted)
    np.testing.assert_allclose(traj.centroids[-1], cell_centroids(sim.state), atol=0)
    assert np.abs(traj.centroids[-1] - traj.centroids[0]).max() > 1e-6       # the cells moved
    # the same trajectory read back from the GSD file (opened once) and from the CSV
    opened, real_open = [], gsd_fl.open
    monkeypatch.setattr(gsd_fl, "open", lambda *a, **k: opened.append(a or k) or real_open(*a, **k))
    from_file = Trajectory.from_gsd(tmp_path / "run.gsd")
    assert len(opened) == 1
    monkeypatch.undo()
    assert len(gsd.open(tmp_path / "run.gsd", "r")) == len(wanted)
    np.testing.assert_array_equal(from_file.times, traj.times)
    np.testing.assert_allclose(from_file.centroids, traj.centroids, atol=1e-12)
    np.testing.assert_array_equal(from_file.cell_replica, [0] * 32 + [1] * 32)
    from_csv = Trajectory.from_recording(Recorder.read_csv(tmp_path / "cells.csv"))
    np.testing.assert_array_equal(from_csv.times, traj.times)
    np.testing.assert_allclose(from_csv.centroids, traj.centroids, atol=1e-12)
    part = Trajectory.from_gsd(tmp_path / "run.gsd", frames=[0, -1])
    np.testing.assert_array_equal(part.times, [0, 300])
    # the measures run on it and are sane
    m = msd(traj)
    qs = self_overlap(traj)
    assert m.value[0] == 0 and np.all(m.value[1:] > 0) and np.all(m.value < 1.0)
    assert qs.value[0] == 1.0 and np.all((qs.value >= 0) & (qs.value <= 1))
    # direct computation for the last frame, replica by replica
    rep = traj.cell_replica
    back = remove_rigid_rotation(traj.centroids[0], traj.centroids[-1], rep)
    d = np.linalg.norm(back - traj.centroids[0], axis=1)
    np.testing.assert_allclose(m.value[-1], np.mean(d ** 2), rtol=1e-12)
    np.testing.assert_allclose(qs.per_replica[-1], [np.mean(d[rep == r] <= 0.5) for r in (0, 1)])
    np.testing.assert_allclose(qs.value, qs.per_replica.mean(axis=1))
    if qs.value.min() > 1 / math.e:
        with pytest.warns(NoRelaxationWarning):
            assert math.isnan(qs.tau_alpha())
    assert Trajectory.from_recording(rec, dt=0.02).times[-1] == pytest.approx(6.0)


def test_recorder_continues_from_a_later_timestep():
    sim = make_sim()
    sim.run(10)
    rec = Recorder.log_spaced(100, points_per_decade=5, start=sim.timestep)
    sim.operations.writers.append(rec)            # attached at t = 10: records the origin now
    assert rec.timesteps.tolist() == [10]
    sim.run(100)
    np.testing.assert_array_equal(rec.timesteps, 10 + log_spaced_times(100, 5))
    rec.record(sim)                                # already recorded at 110: skipped
    assert len(rec) == len(log_spaced_times(100, 5))
    with pytest.raises(ValueError, match="trigger"):
        Recorder()
    with pytest.raises(RuntimeError, match="nothing"):
        Trajectory.from_recording(Recorder(5))


def test_analysis_reexports_the_core_and_writer_names():
    assert svm.analysis.cell_shapes is svm.shapes.cell_shapes
    assert svm.analysis.mean_shape_index is svm.shapes.mean_shape_index
    assert svm.analysis.cell_centroids is cell_centroids
    assert svm.analysis.Recorder is svm.plugins.writers.Recorder is Recorder
    assert svm.analysis.log_spaced_times is log_spaced_times
    assert svm.analysis.OnTimesteps is OnTimesteps


def test_trajectory_validation():
    rng = np.random.default_rng(10)
    x, rep, radius = ensemble(rng, 10, 2)
    with pytest.raises(ValueError, match="increase"):
        Trajectory([0, 0], np.stack([x, x]), rep, radius)
    with pytest.raises(ValueError, match="radius"):
        Trajectory([0], x[None], rep, radius[:1])
    with pytest.raises(ValueError, match="centroids"):
        Trajectory([0, 1], x[None], rep, radius)
    traj = Trajectory([0, 1, 2], np.stack([x, x, x]), rep, radius)
    assert traj.n_replicas == 2 and traj.n_cells == 20 and len(traj) == 3
    np.testing.assert_allclose(traj.length_unit, 1.0)
    np.testing.assert_allclose(traj.without_rotation().centroids, traj.centroids, atol=1e-12)


# ------------------------------------------------------------------------------------ GPU
@pytest.mark.gpu
def test_centroids_and_recorder_on_gpu():
    cpu = svm.init.random_tiling(100, replicas=3, seed=4)
    gpu = cpu.to("gpu")
    for method in ("area", "vertex"):
        np.testing.assert_allclose(cell_centroids(gpu, method), cell_centroids(cpu, method), rtol=0, atol=1e-12)
    sim = svm.Simulation(device="gpu", seed=1)
    sim.state = svm.init.random_tiling(32, replicas=2, seed=2)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    rec = Recorder.log_spaced(50, points_per_decade=5)
    sim.operations.writers.append(rec)
    sim.run(50)
    np.testing.assert_array_equal(rec.timesteps, log_spaced_times(50, 5))
    traj = Trajectory.from_recording(rec)
    assert isinstance(traj.centroids, np.ndarray)
    np.testing.assert_allclose(traj.centroids[-1], cell_centroids(sim.state.to("cpu")), atol=1e-12)
