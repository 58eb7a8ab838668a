"""A user-written Force plugin, a line tension on every edge, used in a real script.

    python examples/line_tension_plugin.py

The class below is the one walked through in docs/plugins.md (and packaged, identical, in
tests/plugin_example/spherevm_line_tension.py). A script can use a plugin class directly, as here;
a package registers it under the entry-point group ``spherevm.plugins`` so that
``spherevm.plugins.load("line_tension")`` and ``spherevm plugins`` find it.

The script prints:
1. the plugin's energy against Lambda * (sum of geodesic edge lengths) measured independently;
2. its forces against central finite differences of its energy, and their radial part;
3. a minimisation of the vertex model with and without the line tension: since
   kP (P - P0)^2 + Lambda P / 2 = kP (P - (P0 - Lambda / (4 kP)))^2 + const, a fluid tissue
   settles at the shape index p0 - Lambda / 4 (kP = 1, <A> = 1) instead of p0.
"""
import numpy as np

import spherevm as svm
from spherevm.geometry import geodesic_length, geodesic_length_gradient
from spherevm.plugins import Force, ForceResult


class LineTension(Force):
    """Line tension ``Lambda`` on every edge: ``E = Lambda * sum over edges of R * theta_edge``."""

    narrowable = True   # it keeps no per-replica data: minimize may narrow

    def __init__(self, tension=1.0, trigger=None):
        super().__init__(trigger)
        value = float(tension)
        if not np.isfinite(value):
            raise ValueError(f"tension must be finite, got {tension!r}")
        self.tension = value

    def compute(self, state) -> ForceResult:
        xp = state.device.xp
        pos = state.positions
        r = xp.sqrt((pos * pos).sum(axis=1))
        unit = pos / r[:, None]
        radius = state.radius[state.vertex_replica]
        a = unit[:, None, :]                                   # (V, 1, 3) the vertex
        b = unit[state.vertex_neighbors]                       # (V, 3, 3) its three neighbours
        lengths = radius[:, None] * geodesic_length(a, b)      # (V, 3): every edge, once from each end
        half = 0.5 * self.tension * lengths
        energy = xp.bincount(xp.repeat(state.vertex_replica, 3), weights=half.reshape(-1),
                             minlength=state.n_replicas)
        cell_energy = xp.bincount(state.vertex_cells.reshape(-1), weights=half.reshape(-1),
                                  minlength=state.n_cells)
        g = geodesic_length_gradient(a, b).sum(axis=1)         # tangent at each vertex
        forces = -self.tension * (radius / r)[:, None] * g
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    @property
    def loggables(self):
        return {"line_tension_energy": lambda sim: self.energy(sim.state)}

    def __repr__(self):
        return f"LineTension(tension={self.tension})"


def check_energy(state, tension):
    e = svm.topology.edges(state.vertex_neighbors)                       # (E, 2), each edge once
    lengths = state.constraint.edge_lengths(state, e[:, 0], e[:, 1])
    expected = tension * np.bincount(state.vertex_replica_np()[e[:, 0]], weights=lengths,
                                     minlength=state.n_replicas)
    got = LineTension(tension).energy(state)
    print("1. energy per replica           ", np.round(got, 6))
    print("   Lambda * sum of edge lengths ", np.round(expected, 6),
          f"(largest relative difference {np.max(np.abs(got - expected) / expected):.1e})")


def check_forces(state, tension, h=1e-5):
    force = LineTension(tension)
    F = force.forces(state)
    x0 = state.positions.copy()
    rep = state.vertex_replica_np()
    worst = 0.0
    for v in range(0, state.n_vertices, 7):  # a handful of vertices, a demonstration only
        fd = np.zeros(3)
        for d in range(3):
            for sign in (1, -1):
                x = x0.copy()
                x[v, d] += sign * h
                state.positions = x
                fd[d] -= sign * force.energy(state)[rep[v]] / (2 * h)
        worst = max(worst, np.linalg.norm(fd - F[v]) / np.linalg.norm(F[v]))
    state.positions = x0
    radial = np.abs((F * x0).sum(axis=1)) / np.linalg.norm(x0, axis=1) / np.linalg.norm(F, axis=1)
    print(f"2. forces vs central differences: largest relative error {worst:.1e}; "
          f"largest radial part {radial.max():.1e} |F|")


def minimise(p0, tension, n_cells=64, replicas=4, seed=5):
    sim = svm.Simulation(device="auto")
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=seed)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=p0))
    line = None
    if tension:
        line = LineTension(tension)
        sim.operations.forces.append(line)
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.05)
    result = sim.minimize(force_tol=1e-9, max_steps=10_000)
    extra = ""
    if line is not None:
        extra = f", line-tension energy/cell {sim.log('line_tension_energy').mean() / n_cells:.4f}"
    print(f"   Lambda = {tension}: {int(result.converged.sum())}/{replicas} converged, mean shape index "
          f"{result.mean_shape_index.mean():.6f} (expected {p0 - tension / 4:.6f}){extra}")
    return result


def main():
    tension = 0.4
    state = svm.init.random_tiling(32, replicas=2, seed=3)
    check_energy(state, tension)
    check_forces(state, tension)
    print("3. vertex model p0 = 4.6, kr = 1, with and without the line tension:")
    minimise(4.6, 0.0)
    minimise(4.6, tension)
    try:
        cls = svm.plugins.load("line_tension")
        print(f"4. an installed package also registers 'line_tension': {cls.__module__}.{cls.__name__}")
    except ValueError:
        print("4. 'line_tension' is not registered here (pip install tests/plugin_example to register it)")


if __name__ == "__main__":
    main()
