"""The dynamics analysis on the periodic plane: centroids, the Recorder, unwrapped displacements,
drift removal, MSD / Q_s / F_s / tau_alpha on planar trajectories, GSD round trip."""
import numpy as np
import pytest

import spherevm as svm
from spherevm.analysis import (Recorder, Trajectory, cell_centroids, msd, self_intermediate_scattering,
                               self_overlap)
from spherevm.constraints.plane import minimum_image


def _shifted(state, shift):
    """A copy of a planar State with every vertex moved by ``shift`` (2,), wrapped into the box."""
    out = state.copy()
    d = np.zeros(3)
    d[:2] = shift
    out.positions = state.constraint.project_normal(state.positions + d, state.box[state.vertex_replica])
    return out


@pytest.mark.parametrize("method", ["area", "vertex"])
def test_planar_centroids_in_box_and_translate_rigidly(method):
    st = svm.init.random_planar_tiling(24, replicas=2, seed=3)
    c = cell_centroids(st, method=method)
    box = st.box_np()[st.cell_replica_np()]
    assert c.shape == (st.n_cells, 3) and np.all(c[:, 2] == 0)
    assert np.all((c[:, :2] >= 0) & (c[:, :2] < box))
    shift = np.array([0.37 * box[0, 0], -0.81 * box[0, 1]])     # moves many cells across the boundary
    c2 = cell_centroids(_shifted(st, shift), method=method)
    np.testing.assert_allclose(minimum_image(c2[:, :2] - c[:, :2] - shift, box), 0.0, atol=1e-12)
    if method == "vertex":
        np.testing.assert_array_equal(c, st.constraint.cell_centers(st))


def test_planar_area_centroid_of_the_honeycomb_is_the_hexagon_centre():
    st = svm.init.hexagonal_tiling(4, 4)
    a = cell_centroids(st, "area")
    v = cell_centroids(st, "vertex")      # a regular hexagon: both are its centre
    np.testing.assert_allclose(minimum_image(a[:, :2] - v[:, :2], st.box_np()[0]), 0.0, atol=1e-12)


def test_rigid_translation_across_the_boundary_gives_msd_d_squared():
    st = svm.init.random_planar_tiling(32, replicas=2, seed=1)
    L = st.box_np()[0, 0]
    step = np.array([0.3, 0.1])            # sqrt(<A>) = 1; 40 frames carry every cell over the boundary
    frames = [_shifted(st, k * step) for k in range(40)]
    traj = Trajectory.from_states(np.arange(40), frames)
    assert traj.box is not None and traj.radius is None
    d2 = (np.arange(40) * np.linalg.norm(step)) ** 2
    assert d2[-1] > (L / 2) ** 2 * 4                                   # much more than the box
    m = msd(traj, remove_drift=False)
    np.testing.assert_allclose(m.value, d2, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.per_replica, np.repeat(d2[:, None], 2, axis=1), rtol=1e-12, atol=1e-12)
    # unwrapped positions continue straight, the stored centroids stay in the box
    np.testing.assert_allclose(traj.positions[-1, :, :2] - traj.positions[0, :, :2],
                               np.broadcast_to(39 * step, (traj.n_cells, 2)), atol=1e-10)
    assert np.all(traj.centroids[..., :2] < L)
    # the overlap sees every cell leave (|d| > b from frame 2 on) and F_s follows J0(q d)
    q = self_overlap(traj, remove_drift=False)
    assert q.value[1] == 1.0 and np.all(q.value[2:] == 0.0)
    from scipy.special import j0
    f = self_intermediate_scattering(traj, remove_drift=False)
    np.testing.assert_allclose(f.value, j0(2 * np.pi * np.sqrt(d2)), atol=1e-12)


def test_drift_removal_cancels_a_uniform_translation():
    st = svm.init.random_planar_tiling(32, replicas=2, seed=2)
    rng = np.random.default_rng(0)
    frames, states = [st], [st]
    walk = np.zeros(2)
    for _ in range(20):
        walk = walk + rng.normal(scale=0.4, size=2)
        states.append(_shifted(st, walk))
    traj = Trajectory.from_states(np.arange(len(states)), states)
    for measure, zero in ((msd, 0.0), (self_overlap, 1.0), (self_intermediate_scattering, 1.0)):
        np.testing.assert_allclose(measure(traj).value, zero, atol=1e-20 if zero == 0 else 1e-12)   # default: on
        np.testing.assert_allclose(measure(traj, remove_drift=True, origins="all").value, zero, atol=1e-20 if zero == 0 else 1e-12)
    raw = msd(traj, remove_drift=False)
    assert raw.value[-1] > 0.1
    # without_drift gives the same, frame by frame
    fixed = traj.without_drift()
    np.testing.assert_allclose(minimum_image(fixed.centroids[..., :2] - traj.centroids[0, :, :2],
                                             traj.box[traj.cell_replica]), 0.0, atol=1e-10)
    # drift removal takes out only the mean: one replica translated, one not, independent
    mixed = [s.copy() for s in states]
    for s, m in zip(states, mixed):
        m.positions[st.vertex_start[1]:] = st.positions[st.vertex_start[1]:]
    t2 = Trajectory.from_states(np.arange(len(mixed)), mixed)
    pr = msd(t2, remove_drift=False).per_replica
    assert pr[-1, 0] > 0.1 and pr[-1, 1] == 0.0


def test_plane_refuses_rotation_removal_and_sphere_refuses_drift():
    st = svm.init.random_planar_tiling(16, seed=0)
    traj = Trajectory.from_states([0, 1], [st, st])
    with pytest.raises(ValueError, match="no rigid rotation"):
        traj.without_rotation()
    with pytest.raises(ValueError, match="no rigid rotation"):
        msd(traj, remove_rotation=True)
    assert msd(traj, remove_rotation=False).value[1] == 0.0
    sp = svm.init.random_tiling(16, seed=0)
    ts = Trajectory.from_states([0, 1], [sp, sp])
    with pytest.raises(ValueError, match="no centre-of-mass drift"):
        msd(ts, remove_drift=True)
    with pytest.raises(ValueError, match="no centre-of-mass drift"):
        ts.without_drift()
    with pytest.raises(ValueError, match="radius .* or the box"):
        Trajectory([0.0], ts.centroids[:1], ts.cell_replica)
    np.testing.assert_allclose(traj.length_unit, 1.0)


def _brownian_planar(tmp_path=None, steps=400, T=0.05):
    sim = svm.Simulation(device="cpu", seed=4)
    sim.state = svm.init.random_planar_tiling(24, replicas=2, seed=5)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.9))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    sim.minimize(force_tol=1e-8, max_steps=3000)
    sim.operations.integrator = svm.plugins.integrators.Brownian(dt=0.01, T=T)
    rec = Recorder.log_spaced(steps, 6, start=sim.timestep)
    sim.operations.writers.append(rec)
    gsd_path = None
    if tmp_path is not None:
        gsd_path = str(tmp_path / "plane.gsd")
        sim.operations.writers.append(svm.plugins.writers.GSD(rec.trigger, gsd_path))
    sim.run(steps)
    for w in sim.operations.writers:
        w.close()
    return sim, rec, gsd_path


def test_brownian_on_a_relaxed_planar_tiling_gives_a_growing_msd(tmp_path):
    sim, rec, path = _brownian_planar(tmp_path)
    r = rec.recording()
    assert r.radius is None and r.box.shape == (2, 2)
    traj = Trajectory.from_recording(rec, dt=0.01)
    m = msd(traj)
    assert m.value[0] == 0.0 and m.value[-1] > 0
    late = m.value[len(m.value) // 2:]
    assert np.all(np.diff(m.value[1:]) > -0.05 * m.value[1:-1].max()) and late[-1] > 2 * m.value[1]
    q = self_overlap(traj)
    assert q.value[0] == 1.0 and np.all(q.value <= 1.0)
    # GSD frames read back into the same numbers as the Recorder
    back = Trajectory.from_gsd(path)
    np.testing.assert_array_equal(back.times, rec.timesteps.astype(float))
    np.testing.assert_array_equal(back.box, r.box)
    np.testing.assert_allclose(back.centroids, r.centroids, rtol=0, atol=1e-12)
    np.testing.assert_allclose(msd(back).value, msd(Trajectory.from_recording(rec)).value, rtol=1e-10, atol=1e-14)
    # the CSV round trip needs the box
    csv = tmp_path / "c.csv"
    rec2 = Recorder(trigger=1, csv=str(csv))
    rec2.write(sim, 0)
    rec2.write(sim, 1)
    rec2.close()
    back = Recorder.read_csv(csv, box=sim.state.box_np())
    np.testing.assert_allclose(back.centroids, rec2.recording().centroids, rtol=0, atol=1e-14)
    assert Trajectory.from_recording(back).box is not None


def test_tau_alpha_on_a_planar_trajectory():
    # cells hop by a growing random displacement: Q_s falls through 1/e
    st = svm.init.random_planar_tiling(32, replicas=1, seed=7)
    rng = np.random.default_rng(1)
    c0 = cell_centroids(st)
    box = st.box_np()[0]
    times = np.arange(1, 30, dtype=float)
    disp = np.cumsum(rng.normal(scale=0.12, size=(len(times), st.n_cells, 2)), axis=0)
    cents = np.zeros((len(times), st.n_cells, 3))
    cents[..., :2] = np.mod(c0[None, :, :2] + disp, box)
    traj = Trajectory(times, cents, st.cell_replica_np(), box=st.box_np())
    q = self_overlap(traj, remove_drift=False)
    dd = np.linalg.norm(disp - disp[0], axis=-1)
    np.testing.assert_allclose(q.value, (dd <= 0.5).mean(axis=1))
    tau = q.tau_alpha()
    assert np.isfinite(tau) and times[1] - times[0] < tau < times[-1] - times[0]
