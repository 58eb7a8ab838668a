"""Minimise an ensemble of random tilings of the sphere and print one row per replica.

    python examples/minimize_ensemble.py                 # 8 tilings of 64 cells, CPU or GPU
    python examples/minimize_ensemble.py ensemble.gsd    # ... and write a trajectory for OVITO

All replicas live in one State and are minimised together: every step updates all of them in one
vectorised pass, and a replica that has converged stops moving while the others go on. The command ``spherevm minimize`` does the same from the shell (docs/cli.md).
"""
import sys
import time

import numpy as np

import spherevm as svm

N_CELLS = 64        # cells per tissue; the sphere's radius is sqrt(N / 4 pi), so <A> = 1
REPLICAS = 8        # independent tissues, different random tilings
P0 = 4.5            # target shape index: above the rigidity transition, so a zero-energy fluid
KR = 1.0            # area stiffness kA <A> / kP
SEED = 7


def main(out=None):
    sim = svm.Simulation(device="auto", seed=SEED)
    sim.state = svm.init.random_tiling(N_CELLS, replicas=REPLICAS, seed=SEED)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=KR, p0=P0))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.05)
    if out is not None:
        sim.operations.writers.append(svm.plugins.writers.GSD(svm.trigger.Periodic(500), out))

    print(f"{REPLICAS} random tilings of {N_CELLS} cells, p0 = {P0}, kr = {KR}, on {sim.device.name}")
    print("before: energy/cell per replica", np.round(sim.log("energy_per_cell"), 3))

    last = [-1]

    def progress(step, n_done, n_replicas):   # called at every convergence check (every 10 steps)
        if n_done != last[0]:                  # report only when another replica has finished
            print(f"  step {step:5d}: {n_done}/{n_replicas} converged", file=sys.stderr, flush=True)
            last[0] = n_done

    t0 = time.perf_counter()
    result = sim.minimize(force_tol=1e-8, energy_tol=1e-14, max_steps=5000, check_every=10, progress=progress)
    elapsed = time.perf_counter() - t0

    print(result.table())
    print(f"{int(result.converged.sum())}/{REPLICAS} converged in {sim.timestep} steps ({elapsed:.2f} s)")
    print(f"mean shape index over the ensemble: {result.mean_shape_index.mean():.6f} "
          f"(target p0 = {P0}; regular-pentagon bound on this sphere: {svm.analysis.pentagon_perimeter(N_CELLS):.4f})")
    fluid = result.energy_per_cell < 1e-10
    print(f"zero-energy (fluid) replicas: {int(fluid.sum())}/{REPLICAS}")
    if out is not None:
        writer = sim.operations.writers[0]
        if not writer.trigger(sim.timestep):   # the final, minimised frame (unless just written)
            writer.write(sim, sim.timestep)
        writer.close()
        print(f"trajectory: {out}")
    return result


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
