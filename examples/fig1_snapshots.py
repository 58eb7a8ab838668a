"""The paper's Fig. 1: a random tissue before and after minimisation, coloured by shape index.

    python examples/fig1_snapshots.py [--cells 200] [--p0 3.7] [--kr 1.0] [--out fig1.png]

Small N by default (a few seconds on a laptop CPU); the paper's figure uses N = 400 or more.
"""
import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm.render import draw, new_axes  # noqa: E402
from spherevm.shapes import shape_index  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=200)
    parser.add_argument("--p0", type=float, default=3.7)
    parser.add_argument("--kr", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default="fig1.png")
    args = parser.parse_args(argv)

    sim = svm.Simulation(device="auto", seed=args.seed)
    sim.state = svm.init.random_tiling(args.cells, seed=args.seed)
    before = sim.state.to("cpu")
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=args.kr, p0=args.p0))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    result = sim.minimize(force_tol=1e-8, max_steps=20_000)
    after = sim.state.to("cpu")

    q0, q1 = shape_index(before), shape_index(after)
    lo, hi = min(q0.min(), q1.min()), max(q0.max(), q1.max())     # one colour scale for both panels
    fig = plt.figure(figsize=(9, 4.2))
    for i, (state, title) in enumerate([(before, "random tiling"),
                                        (after, f"minimised (p0 = {args.p0}, kr = {args.kr})")]):
        ax = new_axes(fig, state, 1, 2, i + 1)
        mappable = draw(ax, state, vmin=lo, vmax=hi)
        ax.set_title(title)
    fig.colorbar(mappable, ax=fig.axes, shrink=0.7, label="shape index  P / sqrt(A)")
    fig.savefig(args.out, dpi=120)
    print(f"<q> {q0.mean():.3f} -> {q1.mean():.3f}; energy/cell {result.energy_per_cell[0]:.3e}; wrote {args.out}")


if __name__ == "__main__":
    main()
