"""A relaxed tissue on each surface: FIRE + T1 at p0 = 3.7 from a random tiling of about 200 cells
(<A> = 1) on the sphere, the periodic plane, a 3:1 torus, an ellipsoid, a Gaussian bump and the
sinusoid of tests/plugin_example, one picture each (cells coloured by their shape index), 400 px.

    PYTHONPATH=. python3 examples/surfaces_gallery.py [out_folder] [n_cells] [max_steps]

Writes ``surface_<name>.png`` into ``out_folder`` (default docs/figures/) and prints, per surface, the
FIRE steps taken, the largest force left and the mean shape index. CPU, about 10 s on one core.
"""
import pathlib
import sys
import time

import spherevm as svm
from spherevm.constraints import Ellipsoid, GaussianBump, Torus
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1
from spherevm.render import render_state

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "plugin_example"))
from spherevm_sinusoid import Sinusoid  # noqa: E402  (the user's surface, tests/plugin_example)

out = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "docs" / "figures"
n_cells = int(sys.argv[2]) if len(sys.argv) > 2 else 200
max_steps = int(sys.argv[3]) if len(sys.argv) > 3 else 5000

#: the tilings (<A> = 1) and the camera's (elevation, azimuth) in degrees
SURFACES = {
    "sphere": (lambda: svm.init.random_tiling(n_cells, seed=1), (20, 30)),
    "plane": (lambda: svm.init.random_planar_tiling(n_cells, seed=1), (20, 30)),
    "torus": (lambda: svm.init.random_tiling(n_cells, seed=1, surface=Torus(3.0, 1.0)), (40, 30)),
    "ellipsoid": (lambda: svm.init.random_tiling(n_cells, seed=1, surface=Ellipsoid(1.0, 1.5, 2.0)), (20, 30)),
    "bump": (lambda: svm.init.random_tiling(n_cells, seed=1, surface=GaussianBump(2.5, 1.0, 6.0)), (25, 30)),
    "sinusoid": (lambda: svm.init.random_tiling(n_cells, seed=1, surface=Sinusoid(amplitude=1.5, box=10.0)), (35, -60)),
}

out.mkdir(parents=True, exist_ok=True)
for name, (tiling, (elev, azim)) in SURFACES.items():
    start = time.perf_counter()
    sim = svm.Simulation(device="cpu", seed=1)
    sim.state = tiling()
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.7))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    sim.minimize(force_tol=1e-6, max_steps=max_steps)
    force = float(abs(sim.compute_forces()[0]).max())
    shape = float(svm.analysis.mean_shape_index(sim.state)[0])
    path = render_state(sim.state, out / f"surface_{name}.png", size=(4.0, 3.4), dpi=100, elev=elev, azim=azim,
                        title=f"{name}: {sim.state.n_cells} cells, p0 = 3.7")
    print(f"{name:10s} {sim.timestep:5d} FIRE steps, max |F| {force:.1e}, mean shape index {shape:.3f}, "
          f"{time.perf_counter() - start:.1f} s -> {path}")
