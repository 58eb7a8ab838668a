"""The surface's per-replica size: declared by the constraint (size_shape, size_names), kept by the
State as one array (state.size), and carried by files, trajectories and pictures without any of
them knowing the surface. A sphere whose size is declared under another name ("rho", so its
size_key is the generic "size") stands in for a new surface: it must work everywhere a Sphere
does, with the same numbers."""
import gsd.hoomd
import numpy as np
import pytest

import spherevm as svm
from spherevm import gsdio, render
from spherevm.analysis import Trajectory, msd
from spherevm.constraints import Sphere


class RhoSphere(Sphere):
    """A sphere whose one size parameter is named "rho" (size_key "size"), drawn as a plain mesh."""
    name = "rho_sphere"
    size_names = ("rho",)
    drawing = "mesh"


def _on_rho(state, device="cpu"):
    a = state.arrays_np()
    a["size"] = a.pop("radius")
    return svm.State(**a, constraint=RhoSphere(), device=device)


def test_the_size_is_one_array_shaped_by_the_constraint(device):
    s = svm.init.random_tiling(16, replicas=2, seed=1, device=device)
    assert s.constraint.size_shape == () and s.constraint.size_key == "radius"
    assert s.radius is s.size and s.box is None and s.box_np() is None
    assert s.size.shape == (2,) and s.size.dtype == np.float64
    p = svm.init.random_planar_tiling(16, replicas=2, seed=1, device=device)
    assert p.box is p.size and p.radius is None and p.radius_np() is None
    assert p.size.shape == (2, 2) and p.size_np().flags.c_contiguous
    # the host copy follows assignments through either name
    s.radius = s.device.xp.asarray([2.0, 3.0])
    np.testing.assert_array_equal(s.size_np(), [2.0, 3.0])
    s.size = s.device.xp.asarray([4.0, 5.0])
    np.testing.assert_array_equal(s.radius_np(), [4.0, 5.0])
    with pytest.raises(ValueError, match=r"Sphere\(\) has no box: its size is radius \(radius\); assign state.size"):
        s.box = np.ones((2, 2))


def test_a_surface_with_its_own_size_name(device):
    sphere = svm.init.random_tiling(20, replicas=2, seed=3)
    rho = _on_rho(sphere, device)
    assert rho.constraint.size_key == "size" and rho.radius is None and rho.box is None
    np.testing.assert_array_equal(rho.size_np(), sphere.size_np())
    assert rho.arrays_np().keys() == sphere.arrays_np().keys() - {"radius"} | {"size"}
    a = sphere.arrays_np()
    with pytest.raises(ValueError, match=r"^radius is given, but a State on RhoSphere\(\) needs size \(rho per "
                                         r"replica\), the size its constraint declares$"):
        svm.State(**a, constraint=RhoSphere())
    a["size"] = a.pop("radius")
    with pytest.raises(ValueError, match=r"^size must be a scalar or one value per replica \(2 replicas\), got "
                                         r"shape \(2, 2\)$"):
        svm.State(**{**a, "size": np.ones((2, 2))}, constraint=RhoSphere())
    with pytest.raises(ValueError, match=r"^size must be positive and finite, got -1.0$"):
        svm.State(**{**a, "size": [1.0, -1.0]}, constraint=RhoSphere())
    both = svm.State.concatenate([rho, rho.replica(0)])
    np.testing.assert_array_equal(both.size_np(), np.r_[sphere.size_np(), sphere.size_np()[:1]])
    assert rho.select(rho.selection([1])).size_np().tolist() == [sphere.size_np()[1]]


def test_a_new_size_name_goes_through_gsd_under_its_key(tmp_path):
    rho = _on_rho(svm.init.random_tiling(20, replicas=2, seed=3, radius=1.5))
    path = tmp_path / "rho.gsd"
    with gsd.hoomd.open(path, "w") as t:
        gsdio.FrameWriter(t).append(rho, 0, {}, {}, {})
    with gsd.hoomd.open(path) as t:
        assert t.file.chunk_exists(frame=0, name="spherevm/size")
        assert not t.file.chunk_exists(frame=0, name="spherevm/radius")
    back = gsdio.read_state(path)
    assert type(back.constraint) is RhoSphere
    assert back.positions.tobytes() == rho.positions.tobytes()
    np.testing.assert_array_equal(back.size_np(), rho.size_np())


def test_a_trajectory_measures_on_the_constraint_it_is_given():
    sphere = svm.init.random_tiling(24, replicas=2, seed=4)
    later = sphere.copy()
    rng = np.random.default_rng(0)
    step = later.constraint.project_tangent(later.positions, rng.normal(scale=0.05, size=later.positions.shape))
    later.positions = later.constraint.project_normal(later.positions + step, later.size[later.vertex_replica])
    ref = Trajectory.from_states([0, 1], [sphere, later])
    rho = Trajectory.from_states([0, 1], [_on_rho(sphere), _on_rho(later)])
    assert type(rho.constraint) is RhoSphere and rho.radius is None
    for geodesic in (False, True):
        assert msd(rho, geodesic=geodesic).value.tobytes() == msd(ref, geodesic=geodesic).value.tobytes()
    with pytest.raises(ValueError, match="has no centre-of-mass drift to remove"):
        msd(rho, remove_drift=True)
    with pytest.raises(ValueError, match="size is given without its constraint"):
        Trajectory([0], ref.centroids[:1], ref.cell_replica, size=ref.size)
    with pytest.raises(ValueError, match=r"size must have one \(rho\) per replica, shape \(2,\), got \(3,\)"):
        Trajectory([0], ref.centroids[:1], ref.cell_replica, constraint=RhoSphere(), size=np.ones(3))


def test_a_surface_drawn_as_a_mesh(tmp_path):
    rho = _on_rho(svm.init.random_tiling(20, seed=3, radius=1.5))
    out = render.render_state(rho, tmp_path / "rho.png", size=(3.0, 3.0), dpi=40)
    assert (tmp_path / "rho.png").stat().st_size > 0 and out == tmp_path / "rho.png"
    import matplotlib.pyplot as plt
    fig = plt.figure()
    ax = render.new_axes(fig, rho, 1, 1, 1)
    render.draw(ax, rho)
    assert ax.name == "3d" and len(ax.collections[0].get_facecolor()) == rho.n_cells   # every cell, none clipped
    pts = np.concatenate(render.cell_polygons(rho, np.arange(rho.n_cells)))
    limits = np.array([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()])
    assert np.all(limits[:, 0] <= pts.min(axis=0) + 1e-12) and np.all(limits[:, 1] >= pts.max(axis=0) - 1e-12)
    np.testing.assert_allclose(np.diff(limits, axis=1), np.diff(limits, axis=1).max())   # one scale on all axes
    plt.close(fig)


def test_a_radius_function_needs_a_radius():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_planar_tiling(16, seed=0)
    with pytest.raises(ValueError, match=r"RadiusSchedule with a radius function needs a surface sized by one radius "
                                         r"per replica \(a Sphere\), got PeriodicPlane\(\) sized by Lx, Ly; use "
                                         r"mode='constant_area'"):
        sim.operations.updaters.append(svm.plugins.updaters.RadiusSchedule(lambda s: 2.0, trigger=1))
