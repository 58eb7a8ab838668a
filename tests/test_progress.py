"""Progress bars (issue 14.8): tqdm on a terminal with the counts and the ETA, nothing in a log."""
import io
import math
import re
import sys

import pytest

from conftest import fire_simulation
from spherevm import cli
from spherevm.progress import MinimizeBar, RunBar, StageBars
from spherevm.sweeps import SweepProgress, TextProgress


class Terminal(io.StringIO):
    def isatty(self):
        return True


def _sim(replicas=2):
    return fire_simulation(replicas=replicas, seed=4)


def _last(text):
    """The last state of a bar redrawn in place."""
    return re.split(r"[\r\n]+", text.strip())[-1]


def test_run_bar_counts_steps_on_a_terminal_only():
    term, log = Terminal(), io.StringIO()
    sim = _sim()
    with RunBar(stream=term) as on_term, RunBar(stream=log) as in_log:
        sim.run(120, check_every=40, progress=lambda d, t: (on_term(d, t), in_log(d, t)))
    assert re.match(r"run: 100%\|.*\| 120/120 .*steps/s", _last(term.getvalue())), term.getvalue()
    assert log.getvalue() == ""
    quiet = Terminal()
    with RunBar(stream=quiet, enabled=False) as b:
        sim.run(10, progress=b)
    assert quiet.getvalue() == ""


def test_minimize_bar_shows_replicas_step_and_force():
    term = Terminal()
    sim = _sim(replicas=3)
    with MinimizeBar(sim, stream=term) as b:
        result = sim.minimize(force_tol=1e-8, max_steps=400, progress=b)
    last = _last(term.getvalue())                  # the state the minimisation ended in
    stopped = int((result.reason != "max_steps").sum())
    assert 0 < stopped < 3                         # seed 4: the replicas need 440, 390 and 380 steps
    assert last.startswith(f"minimize: {stopped}/3 replicas done"), last
    assert int(re.search(r"step=(\d+)", last).group(1)) == max(result.steps) == 400
    fmax = float(re.search(r"max\|F\|=([0-9.e+-]+)", last).group(1))
    assert fmax == pytest.approx(max(result.max_force), rel=0.01)


def test_stage_bars_one_per_stage():
    term = Terminal()
    with StageBars(stream=term) as bars:
        for stage, total in (("relax", 50), ("production", 200)):
            for done in range(0, total + 1, 25):
                bars(stage, done, total)
    text = term.getvalue()
    assert "dynamics relax: 100%" in text and "50/50" in text
    assert _last(text).startswith("dynamics production: 100%") and "200/200" in _last(text)


def test_sweep_bar_shows_chunks_minimisations_reuse_and_eta():
    term = Terminal()
    bar = TextProgress(term)
    p = SweepProgress(chunks_done=0, chunks_total=3, units_done=8, units_total=32, units_reused=8, elapsed=0.0,
                      cells_done=128, cells_total=768, cells_reused=128)
    bar(p)
    p.chunks_done, p.units_done, p.cells_done, p.elapsed = 1, 16, 256, 2.0
    bar(p)
    bar.bar.refresh()
    mid = _last(term.getvalue())
    assert "chunks 1/3" in mid and "minimisations 16/32 (8 on disk)" in mid and "33.3%" in mid
    assert re.search(r"\[\d\d:\d\d<\d\d:\d\d, chunks", mid), mid    # [elapsed<remaining (ETA), counts]
    assert p.eta == pytest.approx(2.0 * (768 - 256) / 128)           # the same extrapolation, in the callback
    p.chunks_done, p.units_done, p.cells_done = 3, 32, 768
    bar(p)
    bar.close()
    assert "100.0%" in _last(term.getvalue()) and "chunks 3/3" in _last(term.getvalue())
    fresh = SweepProgress(0, 1, 0, 4, 0, 0.0, cells_total=64)
    assert math.isnan(fresh.eta)
    log = io.StringIO()
    off = TextProgress(log)
    off(fresh)
    off.close()
    assert log.getvalue() == ""


@pytest.mark.parametrize("argv,expect", [
    (["minimize", "--cells", "16", "--replicas", "2", "--max-steps", "400"], "minimize: 2/2 replicas done"),
    (["dynamics", "--cells", "16", "--replicas", "1", "--steps", "40", "--relax", "30"], "dynamics production: 100%"),
    (["rigidity", "--cells", "16", "--p0", "3.3", "--replicas", "2", "--workers", "1"], "minimisations 2/2"),
])
def test_commands_draw_bars_on_a_terminal_and_not_with_quiet(argv, expect, tmp_path, monkeypatch, capsys):
    if argv[0] == "rigidity":
        argv = argv + ["--out", str(tmp_path / "sweep"), "--no-plots"]
    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    assert cli.main(argv + ["--device", "cpu"]) == 0
    assert expect in term.getvalue(), term.getvalue()
    if argv[0] == "rigidity":
        argv[argv.index("--out") + 1] = str(tmp_path / "sweep2")
    quiet = Terminal()
    monkeypatch.setattr(sys, "stderr", quiet)
    assert cli.main(argv + ["--device", "cpu", "--quiet"]) == 0
    assert quiet.getvalue() == ""
    capsys.readouterr()
