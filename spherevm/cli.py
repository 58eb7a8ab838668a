"""The ``spherevm`` command (also ``python -m spherevm``).

Subcommands::

    spherevm minimize [--cells N] [--replicas R] [--p0 P] [--kr K] [--seed S] [--out run.gsd] ...
    spherevm dynamics --cells N --p0 P --kr K --T T --dt DT --steps S [--out run.gsd] [--csv msd.csv]
    spherevm info [--json]
    spherevm plugins

Bad arguments and bad input caught by the library end with one line on standard error,
``spherevm: error: ...``, and exit status 2; a failure while a minimisation runs gives status 1.
No traceback is shown unless ``--debug`` is given before the subcommand. See docs/cli.md.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

PROG = "spherevm"
COMMANDS_METAVAR = "{minimize,dynamics,rigidity,info,plugins}"
USAGE_ERROR = 2     # bad arguments or bad input
RUNTIME_ERROR = 1   # something failed while running


class CLIError(Exception):
    """A failure to report as one line, ``spherevm: error: <message>``, with an exit status."""

    def __init__(self, message, code=USAGE_ERROR):
        super().__init__(message)
        self.message = message
        self.code = code


def _one_line(exc) -> str:
    text = " ".join(part.strip() for part in str(exc).splitlines() if part.strip())
    return text or type(exc).__name__


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error becomes a CLIError (one line, no usage dump, no SystemExit)."""

    def error(self, message):
        if message.startswith(f"argument {COMMANDS_METAVAR}: invalid choice:"):
            message = "unknown command" + message.split("invalid choice", 1)[1]
        raise CLIError(message, USAGE_ERROR)


# ------------------------------------------------------------------------------------ argument types
def _integer(lo):
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lo}, got {text!r}") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"must be an integer >= {lo}, got {text!r}")
        return value
    parse.__name__ = f"integer >= {lo}"
    return parse


def _real(lo=0.0, strict=False):
    bound = f"> {lo:g}" if strict else f">= {lo:g}"

    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number {bound}, got {text!r}") from None
        if not math.isfinite(value) or value < lo or (strict and value == lo):
            raise argparse.ArgumentTypeError(f"must be a finite number {bound}, got {text!r}")
        return value
    parse.__name__ = f"number {bound}"
    return parse


# ------------------------------------------------------------------------------------ the parser
def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Vertex models of confluent tissue on a sphere.",
                     epilog="Run 'spherevm <command> --help' for a command's options. Docs: docs/cli.md")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"spherevm {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback on errors instead of one line")
    sub = parser.add_subparsers(dest="command", metavar=COMMANDS_METAVAR, parser_class=_Parser)

    m = sub.add_parser("minimize", help="minimise an ensemble of random tilings with FIRE",
                       description="Minimise R random tilings of N cells with the vertex model "
                                   "E/(kP <A>) = sum kr (a - 1)^2 + (p - p0)^2 and print one row per replica. "
                                   "Progress goes to standard error, the table to standard output.")
    g = m.add_argument_group("system")
    g.add_argument("--cells", "-N", type=_integer(4), default=64, metavar="N",
                   help="cells per replica, >= 4 (default: %(default)s)")
    g.add_argument("--replicas", "-R", type=_integer(1), default=4, metavar="R",
                   help="independent tilings, minimised together (default: %(default)s)")
    g.add_argument("--seed", type=_integer(0), default=0, help="random seed of the tilings (default: %(default)s)")
    g.add_argument("--p0", type=_real(0.0), default=3.8, metavar="P",
                   help="target shape index p0 = P0/sqrt(<A>), >= 0 (default: %(default)s)")
    g.add_argument("--kr", type=_real(0.0), default=1.0, metavar="K",
                   help="area stiffness kr = kA <A>/kP, >= 0 (default: %(default)s)")
    g.add_argument("--t1", type=_real(0.0, strict=True), default=0.04, metavar="THRESHOLD",
                   help="T1 neighbour exchanges of edges shorter than THRESHOLD (units of sqrt(<A>)), "
                        "new edges 3 x THRESHOLD long (default: %(default)s)")
    g.add_argument("--no-t1", dest="t1", action="store_const", const=None,
                   help="no T1 exchanges (edges may then collapse and stall the minimisation)")
    g = m.add_argument_group("minimiser")
    g.add_argument("--dt", type=_real(0.0, strict=True), default=0.02, help="FIRE time step, > 0 (default: %(default)s)")
    g.add_argument("--force-tol", type=_real(0.0), default=1e-8,
                   help="a replica converges when its largest vertex force is below this (default: %(default)s)")
    g.add_argument("--energy-tol", type=_real(0.0), default=1e-14,
                   help="... or its energy per cell below this (default: %(default)s)")
    g.add_argument("--max-steps", type=_integer(0), default=20000, help="step limit (default: %(default)s)")
    g.add_argument("--check-every", type=_integer(1), default=10,
                   help="steps between convergence checks and progress updates (default: %(default)s)")
    g = m.add_argument_group("output")
    g.add_argument("--out", "-o", default=None, metavar="FILE.gsd",
                   help="write a GSD trajectory (first frame, every --write-every steps, last frame)")
    g.add_argument("--write-every", type=_integer(0), default=1000, metavar="STEPS",
                   help="frame period of --out; 0 writes the first and last frames only (default: %(default)s)")
    g.add_argument("--device", choices=("cpu", "gpu", "auto"), default="auto",
                   help="where to run; auto takes the GPU when CuPy sees one (default: %(default)s)")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress or summary on standard error")
    m.set_defaults(func=cmd_minimize)

    d = sub.add_parser("dynamics", help="Brownian dynamics: MSD, self-overlap and tau_alpha (the paper's Fig. 3)",
                       description="Relax random tilings with FIRE + T1, equilibrate, then run overdamped Brownian "
                                   "dynamics at temperature T with T1 exchanges; record cell centroids at log-spaced "
                                   "times, and report MSD, self-overlap Q_s and tau_alpha (Q_s = 1/e) in the "
                                   "co-rotating frame.")
    g = d.add_argument_group("system")
    g.add_argument("--cells", "-N", type=_integer(4), default=64, metavar="N", help="cells per replica (default: %(default)s)")
    g.add_argument("--replicas", "-R", type=_integer(1), default=4, metavar="R",
                   help="independent tissues, averaged (default: %(default)s)")
    g.add_argument("--seed", type=_integer(0), default=0, help="random seed (default: %(default)s)")
    g.add_argument("--p0", type=_real(0.0), default=3.775, metavar="P", help="target shape index (default: %(default)s)")
    g.add_argument("--kr", type=_real(0.0), default=0.0, metavar="K", help="area stiffness (default: %(default)s)")
    g = d.add_argument_group("dynamics")
    g.add_argument("--T", "-T", dest="T", type=_real(0.0), default=0.01, help="temperature, >= 0 (default: %(default)s)")
    g.add_argument("--dt", type=_real(0.0, strict=True), default=0.05, help="time step, > 0 (default: %(default)s)")
    g.add_argument("--steps", type=_integer(1), default=5000, help="production steps (default: %(default)s)")
    g.add_argument("--equilibrate", type=_integer(0), default=None, metavar="STEPS",
                   help="equilibration steps before production (default: steps/10)")
    g.add_argument("--relax", type=_integer(0), default=5000, metavar="STEPS",
                   help="FIRE steps of the initial relaxation, 0 to skip (default: %(default)s)")
    g.add_argument("--b", type=_real(0.0, strict=True), default=0.5, help="self-overlap window, sqrt(<A>) (default: %(default)s)")
    g = d.add_argument_group("output")
    g.add_argument("--out", "-o", default=None, metavar="FILE.gsd", help="GSD trajectory of the production run")
    g.add_argument("--csv", default=None, metavar="FILE.csv", help="time, MSD and Q_s (default: next to --out, else none)")
    g.add_argument("--device", choices=("cpu", "gpu", "auto"), default="auto", help="where to run (default: %(default)s)")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress on standard error")
    d.set_defaults(func=cmd_dynamics)

    try:
        from .sweeps import add_cli as add_rigidity
        add_rigidity(sub)
    except ImportError:
        pass

    i = sub.add_parser("info", help="versions, and the device that --device auto picks",
                       description="Print the versions of spherevm and its dependencies and what the "
                                   "GPU path (CuPy, CUDA) can use on this machine.")
    i.add_argument("--json", action="store_true", help="print one JSON object instead")
    i.set_defaults(func=cmd_info)

    p = sub.add_parser("plugins", help="list the available plugins (built-in and entry points)",
                       description="List every plugin by name: the built-ins and those registered by "
                                   "installed packages under the entry-point group 'spherevm.plugins'.")
    p.set_defaults(func=cmd_plugins)
    return parser


# ------------------------------------------------------------------------------------ minimize
class _Progress:
    """The ``progress`` callback of Simulation.minimize, drawn on standard error.

    On a terminal one line is redrawn in place (at most ten times a second); otherwise a line is
    printed at the first check, when a replica finishes, every 5 seconds in the first minute and
    every 30 seconds after that, and at the end.
    """

    def __init__(self, sim, max_steps, stream, enabled=True):
        from .progress import StatusLine
        self.sim, self.max_steps, self.enabled = sim, max_steps, enabled
        self.status = StatusLine(stream)
        self.tty = enabled and self.status.tty
        self.start = self.last = time.monotonic()
        self.last_done = None
        self.drawn = False

    def __call__(self, step, n_done, n_replicas):
        if not self.enabled:
            return
        now = time.monotonic()
        final = n_done == n_replicas or step >= self.max_steps
        if self.tty:
            show = final or now - self.last >= 0.1 or not self.drawn
        else:
            heartbeat = 5.0 if now - self.start < 60.0 else 30.0
            show = final or n_done != self.last_done or now - self.last >= heartbeat
        if not show:
            return
        self.last, self.last_done = now, n_done
        fmax = float(self.sim.device.to_numpy(self.sim.max_force()).max())  # forces are cached: cheap
        line = (f"minimize: step {step:>{len(str(self.max_steps))}d}/{self.max_steps}  "
                f"done {n_done}/{n_replicas}  max|F| {fmax:.2e}  {now - self.start:6.1f} s")
        self.status.show(line)
        self.drawn = True

    def close(self):
        self.status.close()


def _check_out_path(path):
    """Fail early (before any work) when --out cannot be written."""
    if not path:
        raise CLIError("argument --out: expected a file name, got ''")
    full = os.path.abspath(path)
    if os.path.isdir(full):
        raise CLIError(f"argument --out: {path!r} is a directory; give a file name such as run.gsd")
    folder = os.path.dirname(full)
    if not os.path.isdir(folder):
        raise CLIError(f"argument --out: folder {folder!r} does not exist; create it first")
    if not os.access(folder, os.W_OK | os.X_OK) or (os.path.exists(full) and not os.access(full, os.W_OK)):
        raise CLIError(f"argument --out: cannot write {path!r} (permission denied)")


def _format_table(result) -> str:
    cols = ("replica", "energy/cell", "<P/sqrt(A)>", "max|F|", "converged", "reason", "steps")
    rows = []
    for r in range(len(result.converged)):
        rows.append((str(r), f"{result.energy_per_cell[r]:.6e}", f"{result.mean_shape_index[r]:.6f}",
                     f"{result.max_force[r]:.3e}", "yes" if result.converged[r] else "no",
                     str(result.reason[r]), str(int(result.steps[r]))))
    widths = [max(len(c), *(len(row[i]) for row in rows)) for i, c in enumerate(cols)]
    left = {4, 5}  # text columns
    def fmt(row):
        return "  ".join(v.ljust(w) if i in left else v.rjust(w) for i, (v, w) in enumerate(zip(row, widths))).rstrip()
    return "\n".join([fmt(cols)] + [fmt(row) for row in rows])


def cmd_minimize(args) -> int:
    import spherevm as svm
    from .trigger import On, Periodic

    if args.out is not None:
        _check_out_path(args.out)
        import importlib.util
        if importlib.util.find_spec("gsd") is None:  # the GSD writer needs it: fail before any work
            raise CLIError("argument --out: writing GSD files needs the 'gsd' package (pip install gsd)")
    err = sys.stderr
    # set-up: anything the library refuses here is bad input (status 2)
    try:
        device = svm.device.resolve(args.device)
        sim = svm.Simulation(device=device, seed=args.seed)
        sim.state = svm.init.random_tiling(args.cells, replicas=args.replicas, seed=args.seed)
        sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=args.kr, p0=args.p0))
        if args.t1 is not None:
            sim.operations.updaters.append(svm.plugins.updaters.T1(threshold=args.t1, new_length=3.0 * args.t1))
        sim.operations.integrator = svm.plugins.integrators.FIRE(dt=args.dt)
        writer = None
        if args.out is not None:
            trigger = Periodic(args.write_every) if args.write_every > 0 else On(0)
            writer = svm.plugins.writers.GSD(args.out, trigger=trigger)
            sim.operations.writers.append(writer)
    except (ValueError, TypeError, RuntimeError, OSError) as exc:
        raise CLIError(_one_line(exc), USAGE_ERROR) from exc

    if not args.quiet:
        err.write(f"spherevm: minimizing {args.replicas} replica(s) of {args.cells} cells, p0={args.p0:g} "
                  f"kr={args.kr:g}{'' if args.t1 is None else f' t1={args.t1:g}'} on {device.name}"
                  f"{'' if args.out is None else f', writing {args.out}'}\n")
        err.flush()
    progress = _Progress(sim, args.max_steps, err, enabled=not args.quiet)
    t0 = time.perf_counter()
    # the run: a failure here is a runtime failure (status 1)
    try:
        try:
            result = sim.minimize(force_tol=args.force_tol, energy_tol=args.energy_tol,
                                  max_steps=args.max_steps, check_every=args.check_every, progress=progress)
        finally:
            progress.close()
        if writer is not None:
            if not writer.trigger(sim.timestep):  # the last frame, unless the trigger just wrote it
                writer.write(sim, sim.timestep)
            writer.close()
    except Exception as exc:
        raise CLIError(f"minimization failed at step {sim.timestep}: {_one_line(exc)}", RUNTIME_ERROR) from exc
    finally:  # also on Ctrl-C: every frame written so far stays readable
        if writer is not None:
            try:
                writer.close()
            except Exception:
                pass
    elapsed = time.perf_counter() - t0

    print(_format_table(result), file=sys.stdout)
    sys.stdout.flush()
    if not args.quiet:
        n_conv = int(result.converged.sum())
        msg = (f"spherevm: {n_conv}/{len(result.converged)} replica(s) converged in {sim.timestep} steps, "
               f"{elapsed:.2f} s on {device.name}")
        if writer is not None:
            frames = _count_frames(args.out)
            msg += f"; wrote {args.out}" + ("" if frames is None else f" ({frames} frame{'s' * (frames != 1)})")
        err.write(msg + "\n")
    return 0


class _StageProgress:
    """``progress(stage, done, total)`` for long runs: a line every few seconds on standard error."""

    def __init__(self, stream, enabled=True):
        self.stream, self.enabled = stream, enabled
        self.start = self.last = time.monotonic()
        self.stage = None

    def __call__(self, stage, done, total):
        now = time.monotonic()
        if not self.enabled or (stage == self.stage and done < total and now - self.last < 5.0):
            return
        self.stage, self.last = stage, now
        self.stream.write(f"dynamics: {stage:<11} {done:>8d}/{total}  {now - self.start:7.1f} s\n")
        self.stream.flush()


def cmd_dynamics(args) -> int:
    from .protocols import glassy_dynamics
    for path in (args.out, args.csv):
        if path is not None:
            _check_out_path(path)
    csv_path = args.csv or (os.path.splitext(args.out)[0] + ".csv" if args.out else None)
    err = sys.stderr
    if not args.quiet:
        err.write(f"spherevm: dynamics of {args.replicas} x {args.cells} cells, p0={args.p0:g} kr={args.kr:g} "
                  f"T={args.T:g} dt={args.dt:g}, {args.steps} steps\n")
    t0 = time.perf_counter()
    try:
        res = glassy_dynamics(args.cells, args.p0, args.kr, args.T, dt=args.dt, steps=args.steps,
                              replicas=args.replicas, seed=args.seed, device=args.device, relax_steps=args.relax,
                              equilibrate_steps=args.equilibrate, b=args.b, out=args.out,
                              progress=_StageProgress(err, enabled=not args.quiet))
    except (ValueError, TypeError) as exc:
        raise CLIError(_one_line(exc), USAGE_ERROR) from exc
    except Exception as exc:
        raise CLIError(f"dynamics failed: {_one_line(exc)}", RUNTIME_ERROR) from exc
    if csv_path:
        res.write_csv(csv_path)
    print(f"{'time':>12} {'MSD':>12} {'Q_s':>8}")
    for t, m, q in zip(res.lag, res.msd, res.self_overlap):
        print(f"{t:12.5g} {m:12.5g} {q:8.4f}")
    tau = "not reached (Q_s stays above 1/e: run longer)" if not np.isfinite(res.tau_alpha) else f"{res.tau_alpha:.5g}"
    print(f"tau_alpha = {tau}")
    if not args.quiet:
        err.write(f"spherevm: done in {time.perf_counter() - t0:.1f} s"
                  f"{'' if csv_path is None else f'; wrote {csv_path}'}{'' if args.out is None else f' and {args.out}'}\n")
    return 0


def _count_frames(path):
    try:
        import gsd.hoomd
        with gsd.hoomd.open(path, "r") as traj:
            return len(traj)
    except Exception:
        return None


# ------------------------------------------------------------------------------------ info
def _version(dist):
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version(dist)
    except PackageNotFoundError:
        return None


def _cuda_version(raw):
    """CUDA encodes versions as 1000 * major + 10 * minor (12040 -> '12.4')."""
    try:
        n = int(raw)
    except (TypeError, ValueError):
        return str(raw)
    return f"{n // 1000}.{(n % 1000) // 10}"


def collect_info() -> dict:
    import platform

    import spherevm
    from . import device
    from .provenance import source_fingerprint

    facts = device.info()
    out = {
        "spherevm": spherevm.__version__,
        "spherevm_code": source_fingerprint(),
        "spherevm_path": os.path.dirname(os.path.abspath(spherevm.__file__)),
        "python": f"{facts['python']} ({sys.executable})",
        "platform": platform.platform(),
        "numpy": facts["numpy"],
        "scipy": facts["scipy"],
        "gsd": _version("gsd"),
        "trimesh": _version("trimesh"),
        "cupy": facts.get("cupy"),
        "cuda_runtime": _cuda_version(facts["cuda_runtime"]) if facts.get("cuda_runtime") else None,
        "cuda_driver": None,
        "gpus": facts.get("gpus", []),
        "gpu_usable": bool(facts.get("gpu_usable")),
        "gpu_error": facts.get("gpu_error"),
        "auto_device": facts["default_device"],
    }
    if out["cupy"]:
        try:
            import cupy
            out["cuda_driver"] = _cuda_version(cupy.cuda.runtime.driverGetVersion())
        except Exception:
            pass
    return out


def cmd_info(args) -> int:
    facts = collect_info()
    if args.json:
        print(json.dumps(facts, indent=2))
        return 0
    missing = "not installed"
    cupy = facts["cupy"] or missing
    rows = [
        ("spherevm", f"{facts['spherevm']}, code {facts['spherevm_code']} ({facts['spherevm_path']})"),
        ("python", facts["python"]),
        ("platform", facts["platform"]),
        ("numpy", facts["numpy"]),
        ("scipy", facts["scipy"]),
        ("gsd", facts["gsd"] or missing),
        ("trimesh", facts["trimesh"] or missing),
        ("cupy", cupy),
    ]
    if facts["cupy"]:
        rows.append(("cuda runtime", facts["cuda_runtime"] or "unknown"))
        rows.append(("cuda driver", facts["cuda_driver"] or "unknown"))
        rows.append(("gpus", ", ".join(facts["gpus"]) or "none"))
    gpu = "yes" if facts["gpu_usable"] else "no"
    if not facts["gpu_usable"]:
        gpu += (f" ({facts['gpu_error']})" if facts.get("gpu_error") else
                " (CuPy not installed: pip install 'spherevm[gpu]')" if not facts["cupy"] else "")
    rows.append(("gpu usable", gpu))
    rows.append(("device auto", f"{facts['auto_device']}  (what --device auto / device='auto' picks)"))
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key.ljust(width)}  {value}")
    return 0


# ------------------------------------------------------------------------------------ plugins
def list_plugins():
    """Rows ``(name, kind, source)`` for every registered plugin (see :func:`spherevm.plugins.describe`)."""
    from . import plugins
    return plugins.describe()


def cmd_plugins(args) -> int:
    rows = [("name", "kind", "source")] + list_plugins()
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows if not r[1].startswith("broken"))
    for name, kind, source in rows:
        print(f"{name.ljust(w0)}  {kind.ljust(w1)}  {source}".rstrip())
    return 0


# ------------------------------------------------------------------------------------ entry point
def _report(message):
    sys.stderr.write(f"{PROG}: error: {message}\n")
    sys.stderr.flush()


def main(argv=None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(None if argv is None else [os.fspath(a) for a in argv])
    except CLIError as exc:
        _report(exc.message)
        return exc.code
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else USAGE_ERROR)
    if args.command is None:
        _report("no command given; choose one of: minimize, dynamics, rigidity, info, plugins (see spherevm --help)")
        return USAGE_ERROR
    try:
        return int(args.func(args) or 0)
    except CLIError as exc:
        if args.debug:
            raise
        _report(exc.message)
        return exc.code
    except KeyboardInterrupt:
        sys.stderr.write(f"\n{PROG}: interrupted\n")
        return 130
    except BrokenPipeError:  # e.g. `spherevm plugins | head -1`: the reader left, nothing to report
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 0
    except (ValueError, TypeError, FileNotFoundError) as exc:
        if args.debug:
            raise
        _report(_one_line(exc))
        return USAGE_ERROR
    except Exception as exc:
        if args.debug:
            raise
        _report(f"{type(exc).__name__}: {_one_line(exc)} (rerun as 'spherevm --debug ...' for the traceback)")
        return RUNTIME_ERROR


if __name__ == "__main__":
    sys.exit(main())
