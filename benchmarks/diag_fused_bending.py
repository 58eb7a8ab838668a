"""The bending force's fused stage against the step-by-step kernels, one printout for a GPU run.

    python benchmarks/diag_fused_bending.py

Prints, on a sphere ensemble of 300 and 60 cells (the vertex model at kr = 1, p0 = 3.75, with T1):

1. the fused kernel's shared-memory layout (tissue_steps.STEP_LAYOUT's offsets for the largest
   tissue, in doubles) and its forces' aggregate (the stages' calls with their region offsets);
2. one step at T = 0 (no noise), fused and step by step from the same State, T1 off then on, for
   the vertex model + Bending(2.0) and for Bending(2.0) alone: the largest difference of the two
   steps' positions per tissue (0 and "bitwise" where the fused stage is right) and the step's
   largest move;
3. Bending(2.0) at T = 0.2 (the parameters the bending tests first had): the timestep at which each
   of the fused, step-by-step and NumPy (CPU) paths stops with an exploding step, or "ok";
4. the bending tests' runs (200 hot steps, tests/test_tissue_steps.py's ARRANGEMENTS) and their
   minimisation (FIRE + T1), fused against step by step: bitwise or the largest difference.
Needs a GPU (Hopper, for the fused steps).
"""
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests"))

import spherevm as svm  # noqa: E402
from spherevm import tissue_steps  # noqa: E402
from spherevm.constraints.kernels import keeps_directions  # noqa: E402
from spherevm.plan import Plan  # noqa: E402
from spherevm.plugins.forces import Bending, VertexModel  # noqa: E402
from spherevm.plugins.integrators import Brownian  # noqa: E402
from spherevm.plugins.updaters import T1  # noqa: E402

SIZES = (300, 60)


def ensemble():
    return svm.State.concatenate([svm.init.random_tiling(n, seed=3 + i) for i, n in enumerate(SIZES)])


def simulation(device, forces, T, t1=True):
    sim = svm.Simulation(device=device, seed=11)
    sim.state = ensemble()
    sim.operations.forces.extend(forces)
    if t1:
        sim.operations.updaters.append(T1())
    sim.operations.integrator = Brownian(dt=0.01, T=T)
    return sim


def pair(B=2.0):
    return [VertexModel.dimensionless(kr=1.0, p0=3.75), Bending(B)]


def alone(B=2.0):
    return [Bending(B)]


def print_layout():
    import cupy as cp
    sim = simulation("gpu", pair(), 0.0)
    found = tissue_steps.stages(Plan(sim))
    forces = found[0]
    state = sim.state
    n_sm = tissue_steps.device_limits(cp.cuda.Device().id)[2]
    cluster, shared, threads, bound = tissue_steps.layout(state, False, n_sm, found)
    nv, nc = int(state.vertices_per_replica.max()), int(state.cells_per_replica.max())
    values = dict(nv=nv, nc=nc, kept=nv if keeps_directions(state.constraint) else 0, vchunk=-(-nv // cluster),
                  cd=sum(s.cell_doubles for s in forces), md=sum(s.neighbour_doubles for s in forces))
    print(f"stages: {[(s.struct, s.cell_doubles, s.neighbour_doubles, s.extra) for s in forces]}")
    print(f"layout: cluster {cluster}, shared {shared} bytes, {threads} threads, bound {bound}; {values}")
    at = 0
    for region, size in tissue_steps.STEP_LAYOUT.doubles:
        n = eval(size, {"__builtins__": {}}, values)   # noqa: S307 - the layout's own expressions
        print(f"  {region:6s} at {at:7d} doubles, {n:6d} long")
        at += n
    source = tissue_steps.kernel_source(found, False)
    print("aggregate:")
    for line in source.splitlines():
        if any(f"s{k}." in line for k in range(len(forces))) or "for (int j" in line:
            print("  " + line.strip())


def one_step(forces, t1):
    """Positions after one step at T = 0, fused and step by step."""
    out = []
    for way in (dict(fused=True), dict(graphs=False)):
        sim = simulation("gpu", forces(), 0.0, t1)
        before = sim.state.positions.get()
        sim.run(1, **way)
        out.append((before, sim.state.positions.get(), sim.state.vertex_replica_np()))
    (x0, fused, rep), (_, step, _) = out
    for r in range(len(SIZES)):
        m = rep == r
        d = np.abs(fused[m] - step[m]).max()
        move = np.linalg.norm(step[m] - x0[m], axis=1).max()
        same = "bitwise" if fused[m].tobytes() == step[m].tobytes() else "differs"
        print(f"  tissue {r}: fused - step max |dx| {d:.3e} ({same}), largest move {move:.3e}")


def explosion(device, forces, **way):
    sim = simulation(device, forces(), 0.2)
    try:
        sim.run(10, check_every=1, **way)
    except FloatingPointError as err:
        return str(err).split(";")[0]
    return "ok"


def test_runs():
    from conftest import assert_same_minimizations, minimizations
    from test_tissue_steps import ARRANGEMENTS, MINIMIZE_WAYS, three_runs
    for name, (arrange, T) in ARRANGEMENTS.items():
        try:
            runs = three_runs(ensemble(), 200, T=T, arrange=arrange, check_every=64)
        except FloatingPointError as err:
            print(f"  {name}: {err}")
            continue
        ref, fused = runs[-1][0]["positions"], runs[0][0]["positions"]
        print(f"  {name} (T = {T}): fused {'bitwise' if fused.tobytes() == ref.tobytes() else 'differs'}, "
              f"max |dx| {np.abs(fused - ref).max():.3e}; flips {runs[-1][2][0].sum()}")
    sizes, p0 = (40, 150, 32, 90), np.linspace(3.7, 3.9, 4)
    state = svm.State.concatenate([svm.init.random_tiling(n, seed=3 + i) for i, n in enumerate(sizes)])
    fused, _, step = minimizations(state, p0, MINIMIZE_WAYS, extra=lambda: Bending(1.0),
                                   calls=({"max_steps": 1500, "check_every": 50},))
    d = np.abs(fused["state"]["positions"] - step["state"]["positions"]).max()
    try:
        assert_same_minimizations(fused, step)
        verdict = "the same"
    except AssertionError as err:
        verdict = f"differ ({str(err).splitlines()[0]})"
    print(f"  minimisation: fused and step by step {verdict}, max |dx| {d:.3e}")


def main():
    print("1. the fused kernel")
    print_layout()
    for name, forces in (("vertex model + Bending(2.0)", pair), ("Bending(2.0) alone", alone)):
        for t1 in (False, True):
            print(f"2. one step at T = 0, {name}, T1 {'on' if t1 else 'off'}")
            one_step(forces, t1)
    for name, forces in (("vertex model + Bending(2.0)", pair), ("Bending(2.0) alone", alone)):
        print(f"3. {name} at T = 0.2, 10 steps: fused: {explosion('gpu', forces, fused=True)}; "
              f"step by step: {explosion('gpu', forces, graphs=False)}; NumPy: {explosion('cpu', forces)}")
    print("4. the bending tests' runs, fused against step by step")
    test_runs()


if __name__ == "__main__":
    main()
