"""The parameter checks shared by the library and the command line."""
import math

import numpy as np
import pytest

from spherevm import validation


@pytest.mark.parametrize("value, minimum, expected", [(0, 0, 0), (4, 4, 4), (7.0, 1, 7), (np.int64(3), 1, 3)])
def test_integer_accepts(value, minimum, expected):
    got = validation.integer("n", value, minimum)
    assert got == expected and type(got) is int


@pytest.mark.parametrize("value, minimum, message", [
    (-1, 0, "n must be a non-negative integer, got -1"),
    (3, 4, "n must be an integer >= 4, got 3"),
    (1.5, 1, "n must be an integer >= 1, got 1.5"),
    (True, 0, "n must be a non-negative integer, got True"),
    ("5", 0, "n must be a non-negative integer, got '5'"),
    (None, 0, "n must be a non-negative integer, got None"),
    (math.inf, 0, "n must be a non-negative integer, got inf"),
    (math.nan, 0, "n must be a non-negative integer, got nan"),
])
def test_integer_rejects_naming_the_range(value, minimum, message):
    with pytest.raises(validation.ParameterError) as info:
        validation.integer("n", value, minimum)
    assert str(info.value) == message and isinstance(info.value, ValueError)


def test_real_and_positive():
    assert validation.real("kr", 0) == 0.0 and validation.real("kr", "2.5") == 2.5
    assert validation.positive("dt", 0.1) == 0.1
    for bad in (-1e-300, math.nan, math.inf, "x", None):
        with pytest.raises(ValueError, match=r"kr must be a finite number >= 0, got"):
            validation.real("kr", bad)
    for bad in (0, -1, math.nan, "x"):
        with pytest.raises(ValueError, match=r"dt must be positive and finite, got"):
            validation.positive("dt", bad)
    with pytest.raises(validation.ParameterError) as info:
        validation.real("dt", 0.0, strict=True)
    assert info.value.allowed == "positive and finite" and info.value.name == "dt"


def test_non_negative_arrays():
    assert np.array_equal(validation.non_negative("T", [0.0, 1.0]), [0.0, 1.0])
    with pytest.raises(ValueError, match=r"T must be finite and >= 0"):
        validation.non_negative("T", [[1.0]])


# ------------------------------------------------------------------ simple tilings (spherevm.simplicity)
import re  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm import folding, simplicity  # noqa: E402

from test_fuzz import brute_force_crossings  # noqa: E402
from untangle_fuzz import tiling  # noqa: E402

TILINGS = {"sphere": svm.init.random_tiling, "plane": svm.init.random_planar_tiling}


def _kicked(surface, scale, seed=3):
    """Two 60-cell tilings (of any surface of benchmarks/untangle_fuzz.py) with every vertex kicked
    by ``scale`` sqrt(<A>) (no forces: crossings)."""
    state = tiling(surface, 60, 2, seed)
    con, rng = state.constraint, np.random.default_rng(seed)
    kick = rng.normal(scale=scale * np.sqrt(state.mean_cell_area[0]), size=state.positions.shape)
    size = con.size(state, state.vertex_replica)
    state.positions = con.project_normal(state.positions + con.project_tangent(state.positions, kick, size), size)
    return state


def _swapped(surface):
    """A tiling whose edge 7 vertices into replica 1 has its two ends swapped: the bow tie a step
    makes of an edge that it pushes through zero length."""
    state = TILINGS[surface](60, replicas=2, seed=1)
    u = int(state.vertex_start[1]) + 7
    v = int(state.vertex_neighbors[u, 0])
    pos = state.positions.copy()
    pos[[u, v]] = pos[[v, u]]
    state.positions = pos
    return state, u, v


@pytest.mark.parametrize("surface, scale", [("sphere", 0.3), ("plane", 0.12), ("torus", 0.12), ("ellipsoid", 0.3),
                                            ("bump", 0.2)])
def test_crossings_are_those_a_brute_force_finds(surface, scale):
    state = _kicked(surface, scale)
    cell, i, j = simplicity.self_crossings(state)
    found = set(zip(cell.tolist(), i.tolist(), j.tolist()))
    assert found == brute_force_crossings(state) and len(found) > 10, len(found)
    counts = simplicity.counts(state)
    assert counts["crossed"].sum() == len(set(cell.tolist()))


def test_arcs_meeting_only_at_their_antipodes_do_not_cross():
    deg = np.pi / 180
    a, b = np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]])            # the equator from 0 to 90 degrees

    def meridian(lon):
        return [np.array([[np.cos(10 * deg) * np.cos(lon * deg), np.cos(10 * deg) * np.sin(lon * deg),
                           s * np.sin(10 * deg)]]) for s in (-1, 1)]
    assert simplicity.arcs_cross(a, b, *meridian(45)).all()
    assert not simplicity.arcs_cross(a, b, *meridian(225)).any()


@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_validate_names_the_replica_the_cell_and_the_crossing_edges(surface):
    state, u, v = _swapped(surface)
    with pytest.raises(ValueError, match=r"^replica 1: cell \d+ is not a simple polygon: its edges \d+ -> \d+ and "
                                         r"\d+ -> \d+ cross \(2 such cell\(s\) in all\)$") as info:
        state.validate()
    c = int(re.match(r"replica 1: cell (\d+)", str(info.value)).group(1))
    assert {c for c, _, _ in brute_force_crossings(state)} >= {c}
    state.validate(orientation=False)      # folded cells allowed (kA = 0): crossings too
    iu, islot = folding.inverted_edges(state)
    assert [(int(x), int(state.vertex_neighbors[x, k])) for x, k in zip(iu, islot)] == [(min(u, v), max(u, v))]


@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_a_vertex_pushed_into_its_neighbour_is_caught(surface):
    """Overlap without comparing cells: a vertex moved across its cell's far side, into another
    cell, leaves some cell crossed, inverted or the areas' sum wrong (simplicity's degree argument)."""
    state = TILINGS[surface](60, seed=2)
    con = state.constraint
    pos = state.positions.copy()
    w, c = 10, int(state.vertex_cells[10, 0])
    ring = state.cell_vertices[c, :state.cell_sides[c]]
    far = pos[ring[(list(ring).index(w) + len(ring) // 2) % len(ring)]]
    far = con.unwrap(far[None], pos[w][None], con.size_np(state)[:1])[0]
    pos[w] = con.project_normal((pos[w] + 2.5 * (far - pos[w]))[None], con.size_np(state)[:1])[0]
    state.positions = pos
    with pytest.raises(ValueError, match=r"^replica 0: (cell \d+ is not a simple polygon|cell \d+ has area|the cell)"):
        state.validate()


def _opened():
    """A 16-cell planar tiling whose longest edge along x is pushed past half the box: the State and
    the edge's two vertices."""
    state = svm.init.random_planar_tiling(16, seed=0)
    box = state.box[0]
    u = np.repeat(np.arange(state.n_vertices), 3)
    d = state.constraint.displacement(state, u, state.vertex_neighbors.reshape(-1))
    k = int(np.argmax(np.abs(d[:, 0])))
    a, b = int(u[k]), int(state.vertex_neighbors.reshape(-1)[k])
    pos = state.positions.copy()                    # b pushed along the edge until it passes half the box
    pos[b, 0] = (pos[b, 0] + np.sign(d[k, 0]) * (0.5 * box[0] - abs(d[k, 0]) + 0.05)) % box[0]
    state.positions = pos
    return state, a, b


def test_an_edge_reaching_half_the_box_is_named():
    state, a, b = _opened()
    with pytest.raises(ValueError, match=r"^replica 0: edge \d+ -> \d+ of cell \d+ reached half the box "
                                         r"\[4\.0, 4\.0\]: its minimum image jumped") as info:
        state.validate(orientation=False)
    named = {int(x) for x in re.match(r"replica 0: edge (\d+) -> (\d+)", str(info.value)).groups()}
    assert named == {a, b}
    assert simplicity.counts(state)["open"].sum() == 2      # the two cells on its sides


def test_the_runs_check_catches_an_open_cell_on_both_devices(device):
    """Simulation.check_finite (every check of a run) finds the open cell on either device, with
    State.validate's message: on the GPU the device flags it in the replica summary that the check
    reads anyway, and the host names it then. A closed tiling raises nothing."""
    from spherevm.plugins.forces import VertexModel
    from spherevm.plugins.integrators import Brownian
    state = _opened()[0]
    with pytest.raises(ValueError) as expected:
        state.validate(orientation=False)
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    for with_forces in (False, True):       # the summary from the positions alone, or read with the forces
        if with_forces:
            assert sim.replica_summary()[3] == (1 if device == "gpu" else 0)
        with pytest.raises(ValueError) as found:
            sim.check_finite()
        assert str(found.value) == f"at timestep 0: {expected.value}"
    sim.operations.integrator = Brownian(dt=1e-4, T=0.0)
    with pytest.raises(ValueError, match=r"^at timestep 1: replica 0: edge \d+ -> \d+ of cell \d+ reached half"):
        sim.run(1)
    closed = svm.Simulation(device=device)
    closed.state = svm.init.random_planar_tiling(16, seed=0)
    closed.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    closed.operations.integrator = Brownian(dt=1e-4, T=0.0)
    closed.run(2)
    assert closed.replica_summary()[3] == 0
