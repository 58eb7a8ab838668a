"""The numbers of docs/plugins.md for the example LineTension plugin on a GPU (needs CuPy).

    python benchmarks/line_tension_gpu.py [--shapes 3x64 50x1000] [--seed 1]

Prints, for random tilings of R replicas x N cells (``random_tiling(N, replicas=R, seed=...)``):

1. the plugin's array code (``examples/line_tension_plugin.py``, written with ``state.device.xp``)
   on CuPy against the same code on NumPy: largest relative difference of forces and energies;
2. the fused kernel of docs/plugins.md ("Faster on the GPU"; its source is read from that page,
   so this measures the documented kernel) against NumPy: the same differences;
3. the median time per ``compute`` call of the kernel path and of the array code on CuPy
   (``benchmarks/common.median_time``: 2 warm-up calls, 11 timed, device synchronised).

Device, CuPy and CUDA versions and the date are printed with the table.
"""
from __future__ import annotations

import argparse
import datetime
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "examples"))
from common import median_time  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm.plugins import ForceResult  # noqa: E402
from line_tension_plugin import LineTension  # noqa: E402


def documented_kernel() -> str:
    text = (ROOT / "docs" / "plugins.md").read_text()
    m = re.search(r"```cuda\n(.*?)```", text, re.S)
    if m is None:
        raise SystemExit("no ```cuda block in docs/plugins.md")
    return m.group(1)


class LineTensionKernel(LineTension):
    """The two-path class of docs/plugins.md: the array code on the CPU, the kernel on the GPU."""

    gpu_surfaces = (svm.constraints.Sphere,)
    cu_file = None

    def compute(self, state):
        return self.implementation("compute", state)(state)

    def _compute_cpu(self, state):
        return LineTension.compute(self, state)

    def _compute_gpu(self, state):
        import cupy as cp
        from spherevm.device import launch, load_module, segment_sums
        module = load_module(self.cu_file)
        nv = state.n_vertices
        forces = cp.empty_like(state.positions)
        corner_energy = cp.empty((nv, 3))
        energy = cp.empty(state.n_replicas)
        launch(module.get_function("line_tension"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_replica, state.radius,
                np.int32(nv), np.float64(self.tension), forces, corner_energy, energy,
                *segment_sums(state, "vertices")))
        cell_energy = cp.bincount(state.vertex_cells.reshape(-1), weights=corner_energy.reshape(-1),
                                  minlength=state.n_cells)
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)


def rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", nargs="+", default=["3x64", "50x1000"], help="REPLICASxCELLS")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--tension", type=float, default=0.7)
    args = ap.parse_args(argv)
    import cupy as cp
    gpu = svm.device.resolve("gpu")
    props = cp.cuda.runtime.getDeviceProperties(0)
    print(f"# {datetime.date.today()}  {props['name'].decode()}, CuPy {cp.__version__}, "
          f"CUDA runtime {cp.cuda.runtime.runtimeGetVersion()}, seed {args.seed}, tension {args.tension}")
    with tempfile.TemporaryDirectory() as tmp:
        cu = Path(tmp) / "line_tension.cu"
        cu.write_text(documented_kernel())
        LineTensionKernel.cu_file = cu
        print(f"{'shape':>9} {'xp: forces':>11} {'xp: energy':>11} {'cu: forces':>11} {'cu: energy':>11} "
              f"{'kernel [ms]':>12} {'CuPy xp [ms]':>13}")
        for shape in args.shapes:
            r, n = (int(v) for v in shape.lower().split("x"))
            cpu = svm.init.random_tiling(n, replicas=r, seed=args.seed)
            dev = cpu.to(gpu)
            plain, fused = LineTension(args.tension), LineTensionKernel(args.tension)
            f_np, e_np = plain.forces(cpu), plain.energy(cpu)
            f_xp, e_xp = plain.forces(dev), plain.energy(dev)
            f_cu, e_cu = fused.forces(dev), fused.energy(dev)
            t_cu = median_time(lambda: fused.compute(dev), gpu)
            t_xp = median_time(lambda: plain.compute(dev), gpu)
            print(f"{shape:>9} {rel(f_xp, f_np):11.1e} {rel(e_xp, e_np):11.1e} {rel(f_cu, f_np):11.1e} "
                  f"{rel(e_cu, e_np):11.1e} {1e3 * t_cu:12.3f} {1e3 * t_xp:13.3f}")


if __name__ == "__main__":
    main()
