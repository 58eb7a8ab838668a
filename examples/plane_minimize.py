"""Minimise a random planar periodic tissue (Voronoi tiling, <A> = 1) with FIRE and T1 exchanges,
and print the energy per cell and the mean shape index of each replica.

    PYTHONPATH=. python3 examples/plane_minimize.py [n_cells] [p0]
"""
import sys

import spherevm as svm
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1

n_cells = int(sys.argv[1]) if len(sys.argv) > 1 else 100
p0 = float(sys.argv[2]) if len(sys.argv) > 2 else 3.7

sim = svm.Simulation(device="cpu", seed=1)
sim.state = svm.init.random_planar_tiling(n_cells, replicas=2, seed=0)   # square boxes of area n_cells
sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=p0))
fire = FIRE(dt=0.01, force_tol=1e-10, energy_tol=1e-16)
sim.operations.integrator = fire
sim.operations.updaters.append(T1(trigger=10))
steps = 0
while not fire.done and steps < 100_000:
    sim.run(100)
    steps += 100
energy = sim.compute_forces()[1] / sim.state.cells_per_replica
shape = svm.shapes.mean_shape_index(sim.state)
for r in range(sim.state.n_replicas):
    print(f"replica {r}: box {sim.state.box_np()[r].round(4).tolist()}, energy per cell {energy[r]:.3e}, "
          f"mean shape index {shape[r]:.4f}")
print(f"{steps} FIRE steps, converged: {fire.done}")
