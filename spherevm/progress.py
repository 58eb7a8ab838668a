"""Progress bars for long runs, drawn with tqdm on a terminal and silent elsewhere (a log file, a
pipe, CI), so logs hold only the commands' own start and summary lines.

Each class here is a ``progress`` callback of one long-running function:
:class:`RunBar` for ``Simulation.run``, :class:`MinimizeBar` for ``Simulation.minimize`` and
:class:`StageBars` for :func:`spherevm.protocols.glassy_dynamics`; the sweep's bar is
``spherevm.sweeps.TextProgress``. Call ``close()`` when the run ends (or use ``with``).
"""
from __future__ import annotations

import os
import sys
import time

from tqdm import tqdm


def on_terminal(stream) -> bool:
    """Whether ``stream`` is a terminal (where a bar is redrawn in place)."""
    return bool(getattr(stream, "isatty", None) and stream.isatty())


def _sized(stream) -> bool:
    """Whether the terminal reports its size (a pseudo-terminal may say 0 x 0, and tqdm then
    draws nothing: give it a size instead)."""
    try:
        return min(os.get_terminal_size(stream.fileno())) > 0
    except (AttributeError, OSError, ValueError):
        return False


def bar(total, desc, unit, stream=None, enabled=True, **options) -> tqdm:
    """A tqdm bar on ``stream`` (standard error by default), disabled unless ``enabled`` and the
    stream is a terminal; it follows the terminal's width, or is 100 columns where the size is
    unknown. ``options`` go to tqdm (``initial``, ``smoothing``, ``bar_format``...)."""
    stream = sys.stderr if stream is None else stream
    sized = _sized(stream)
    return tqdm(total=total, desc=desc, unit=unit, file=stream, disable=not (enabled and on_terminal(stream)),
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
    """``progress(done, total)`` of ``Simulation.run``: steps done, rate and ETA."""

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
    at most ten times a second and whenever a replica stops; ``close()`` shows the last call."""

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
    per stage (relax, equilibrate, production), each with its rate and ETA."""

    def __init__(self, desc="dynamics", stream=None, enabled=True):
        self.desc, self.stream, self.enabled = desc, stream, enabled
        self.stage = None

    def __call__(self, stage, done, total):
        if stage != self.stage:
            self.close()
            self.stage = stage
            self._bar = bar(total, f"{self.desc} {stage}", " steps", self.stream, self.enabled)
        _advance(self._bar, done)
