"""Progress bars for long runs, drawn with tqdm: on a terminal as text redrawn in place, in a
Jupyter notebook as tqdm's notebook widget (text in the cell's output where ipywidgets is
missing).

Each class here is a ``progress`` callback of one long-running function:
:class:`RunBar` for ``Simulation.run``, :class:`MinimizeBar` for ``Simulation.minimize`` and
:class:`StageBars` for :func:`spherevm.protocols.glassy_dynamics`; the sweep's bar is
``spherevm.sweeps.TextProgress``. A bar you create is shown wherever its stream goes
(``enabled=True``, the default); the command line passes ``enabled=None``, which draws only where
someone watches (a terminal or a notebook), so logs and pipes hold only the commands' own start
and summary lines; ``enabled=False`` draws nothing. Call ``close()`` when the run ends (or use
``with``).
"""
from __future__ import annotations

import os
import sys
import time

from tqdm import tqdm


def on_terminal(stream) -> bool:
    """Whether ``stream`` is a terminal (where a bar is redrawn in place)."""
    return bool(getattr(stream, "isatty", None) and stream.isatty())


def in_notebook() -> bool:
    """Whether this runs in a Jupyter kernel of a notebook (Jupyter, JupyterLab, VS Code), the test
    of ``tqdm.autonotebook``: IPython's shell is the kernel's, and not a Qt console's or Spyder's."""
    if "ipykernel.zmqshell" not in sys.modules or "IPython" not in sys.modules:
        return False
    if any(name == "QT_API" or name.startswith("SPYDER") for name in os.environ):
        return False
    shell = type(sys.modules["IPython"].get_ipython()).__name__.lower()
    return shell == "zmqinteractiveshell"


def _widgets() -> bool:
    """Whether ipywidgets is there for tqdm's notebook bar."""
    from tqdm import notebook
    return notebook.IProgress is not None


def _sized(stream) -> bool:
    """Whether the terminal reports its size (a pseudo-terminal may say 0 x 0, and tqdm then
    draws nothing: give it a size instead)."""
    try:
        return min(os.get_terminal_size(stream.fileno())) > 0
    except (AttributeError, OSError, ValueError):
        return False


def bar(total, desc, unit, stream=None, enabled=True, **options) -> tqdm:
    """A tqdm bar of ``total`` counts.

    Parameters
    ----------
    stream : where the text bar goes (standard error by default); in a notebook with ipywidgets
        and no ``stream`` given, the bar is tqdm's notebook widget instead
    enabled : True: drawn; None: drawn only on a terminal or in a notebook; False: not drawn
    options : passed to tqdm (``initial``, ``smoothing``, ``bar_format``...)

    Returns
    -------
    The tqdm bar (``disable`` set where it is not drawn). A text bar follows the terminal's width,
    or is 100 columns where the size is unknown.
    """
    notebook = in_notebook()
    widget = notebook and stream is None and _widgets()
    stream = sys.stderr if stream is None else stream
    shown = (notebook or on_terminal(stream)) if enabled is None else bool(enabled)
    if widget:
        from tqdm.notebook import tqdm as notebook_tqdm
        return notebook_tqdm(total=total, desc=desc, unit=unit, disable=not shown, mininterval=0.1, leave=True,
                      **options)
    sized = _sized(stream)
    return tqdm(total=total, desc=desc, unit=unit, file=stream, disable=not shown,
                mininterval=0.1, dynamic_ncols=sized, ncols=None if sized else 100, nrows=None if sized else 24,
                leave=True, **options)


class _Bar:
    """Owns one bar at a time; a context manager that closes it."""

    _bar = None

    def close(self):
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _advance(b, done):
    """Move ``b`` to ``done`` (callbacks report totals so far, tqdm counts increments)."""
    if done > b.n:
        b.update(done - b.n)


class RunBar(_Bar):
    """``progress(done, total)`` of ``Simulation.run``: steps done, rate and ETA (``stream`` and
    ``enabled`` as in :func:`bar`)."""

    def __init__(self, desc="run", stream=None, enabled=True):
        self.desc, self.stream, self.enabled = desc, stream, enabled

    def __call__(self, done, total):
        if self._bar is None:
            self._bar = bar(total, self.desc, " steps", self.stream, self.enabled)
        _advance(self._bar, done)


class MinimizeBar(_Bar):
    """``progress(step, n_done, n_replicas)`` of ``Simulation.minimize``: replicas stopped out of
    all, the step and, given the Simulation, the largest force among the replicas still running
    (``sim.state`` holds only those once narrowed; cached, so cheap to read). Redrawn
    at most ten times a second and whenever a replica stops; ``close()`` shows the last call
    (``stream`` and ``enabled`` as in :func:`bar`)."""

    def __init__(self, simulation=None, desc="minimize", stream=None, enabled=True):
        self.sim, self.desc, self.stream, self.enabled = simulation, desc, stream, enabled
        self.shown = -float("inf")
        self.latest = None

    def __call__(self, step, n_done, n_replicas):
        if self._bar is None:
            self._bar = bar(n_replicas, self.desc, " replicas", self.stream, self.enabled,
                            bar_format="{desc}: {n_fmt}/{total_fmt} replicas done |{bar}| [{elapsed}{postfix}]")
        if self._bar.disable:
            return
        self.latest = (step, n_done)
        if n_done != self._bar.n or time.monotonic() - self.shown >= 0.1:
            self._show()

    def _show(self):
        step, n_done = self.latest
        post = {"step": step}
        if self.sim is not None:
            post["max|F|"] = f"{float(self.sim.device.to_numpy(self.sim.max_force()).max()):.2e}"
        self._bar.set_postfix(post, refresh=False)
        _advance(self._bar, n_done)
        self._bar.refresh()
        self.shown, self.latest = time.monotonic(), None

    def close(self):
        if self._bar is not None and self.latest is not None:
            self._show()
        super().close()


class StageBars(_Bar):
    """``progress(stage, done, total)`` of :func:`spherevm.protocols.glassy_dynamics`: one bar
    per stage (relax, equilibrate, production), each with its rate and ETA (``stream`` and
    ``enabled`` as in :func:`bar`)."""

    def __init__(self, desc="dynamics", stream=None, enabled=True):
        self.desc, self.stream, self.enabled = desc, stream, enabled
        self.stage = None

    def __call__(self, stage, done, total):
        if stage != self.stage:
            self.close()
            self.stage = stage
            self._bar = bar(total, f"{self.desc} {stage}", " steps", self.stream, self.enabled)
        _advance(self._bar, done)


class StageLines:
    """``progress(stage, done, total)`` of :func:`spherevm.protocols.glassy_dynamics` as plain lines,
    for logs: one line per stage at its start and at each further tenth, with the seconds since this
    object was made (``stream``: standard output by default)."""

    def __init__(self, desc="dynamics", stream=None):
        self.desc, self.stream = desc, stream
        self.started, self.last = time.perf_counter(), {}

    def __call__(self, stage, done, total):
        tenth = int(10 * done / max(total, 1))
        if self.last.get(stage) != tenth:
            self.last[stage] = tenth
            print(f"  {self.desc} {stage}: {done}/{total} steps, {time.perf_counter() - self.started:.0f} s",
                  file=self.stream or sys.stdout, flush=True)
