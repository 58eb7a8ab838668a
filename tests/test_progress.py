"""Progress bars (issue 14.8): tqdm with the counts and the ETA; a bar asked for is drawn, the
command line's only on a terminal or in a notebook (nothing in a log); tqdm's notebook widget in a
Jupyter kernel (issue 35.2)."""
import io
import math
import re
import sys
import types

import pytest
import tqdm.notebook

from conftest import fire_simulation
from spherevm import cli
from spherevm import progress
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


def test_run_bar_counts_steps_where_asked_and_on_a_terminal_only_when_automatic():
    term, log, auto_log = Terminal(), io.StringIO(), io.StringIO()
    sim = _sim()
    with RunBar(stream=term) as on_term, RunBar(stream=log) as in_log, RunBar(stream=auto_log, enabled=None) as auto:
        sim.run(120, check_every=40, progress=lambda d, t: (on_term(d, t), in_log(d, t), auto(d, t)))
    for text in (term.getvalue(), log.getvalue()):        # asked for: drawn, a terminal or not
        assert re.match(r"run: 100%\|.*\| 120/120 .*steps/s", _last(text)), text
    assert auto_log.getvalue() == ""                       # automatic: not in a log
    quiet = Terminal()
    with RunBar(stream=quiet, enabled=False) as b:
        sim.run(10, progress=b)
    assert quiet.getvalue() == ""


@pytest.fixture
def kernel(monkeypatch):
    """A fake Jupyter kernel: ipykernel's shell module loaded and IPython's shell the kernel's."""
    class ZMQInteractiveShell:
        pass

    shell = ZMQInteractiveShell()
    monkeypatch.setitem(sys.modules, "ipykernel.zmqshell", types.ModuleType("ipykernel.zmqshell"))
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    for name in [n for n in __import__("os").environ if n == "QT_API" or n.startswith("SPYDER")]:
        monkeypatch.delenv(name)
    return shell


def test_notebook_detection(kernel, monkeypatch):
    assert progress.in_notebook()
    monkeypatch.setenv("QT_API", "pyqt5")                  # a Qt console runs the same kernel
    assert not progress.in_notebook()
    monkeypatch.delenv("QT_API")
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: object()))
    assert not progress.in_notebook()                      # plain IPython in a terminal


def test_not_a_notebook_outside_a_kernel(monkeypatch):
    monkeypatch.delitem(sys.modules, "ipykernel.zmqshell", raising=False)
    assert not progress.in_notebook()


def test_notebook_bar_is_the_widget_where_ipywidgets_is_there(kernel, monkeypatch):
    monkeypatch.setattr(tqdm.notebook, "IProgress", object)            # as if ipywidgets were installed
    made = {}

    class Widget:
        def __init__(self, **kwargs):
            made.update(kwargs)

    monkeypatch.setattr(tqdm.notebook, "tqdm", Widget)
    b = progress.bar(10, "run", " steps", enabled=None)
    assert isinstance(b, Widget) and made["disable"] is False and made["total"] == 10 and "file" not in made
    text = progress.bar(10, "run", " steps", stream=io.StringIO(), enabled=None)   # a stream given: text
    assert not isinstance(text, Widget) and not text.disable


def test_notebook_without_ipywidgets_draws_text_in_the_cell(kernel, monkeypatch):
    monkeypatch.setattr(tqdm.notebook, "IProgress", None)
    cell = io.StringIO()                                   # the kernel's standard error: not a terminal
    monkeypatch.setattr(sys, "stderr", cell)
    with RunBar(enabled=None) as auto:                     # what the command line asks for
        _sim().run(40, check_every=20, progress=auto)
    assert re.match(r"run: 100%\|.*\| 40/40 ", _last(cell.getvalue())), cell.getvalue()


def test_notebook_widget_with_real_ipywidgets(kernel, monkeypatch):
    pytest.importorskip("ipywidgets", reason="ipywidgets draws tqdm's notebook widget")
    monkeypatch.setattr(tqdm.notebook, "display", lambda *a, **k: None, raising=False)   # no front end here
    with RunBar() as b:
        _sim().run(30, check_every=10, progress=b)
        widget = b._bar
    assert isinstance(widget, tqdm.notebook.tqdm)
    meter = widget.container.children[1]                     # ipywidgets.FloatProgress, closed at 30 of 30
    assert (meter.max, meter.value, meter.bar_style) == (30, 30, "success")


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
    off = TextProgress(log, enabled=None)
    off(fresh)
    off.close()
    assert log.getvalue() == ""
    drawn = TextProgress(log)                              # asked for: drawn in a log too
    drawn(fresh)
    drawn.close()
    assert "rigidity:   0.0%" in log.getvalue()


@pytest.mark.parametrize("argv,expect", [
    (["minimize", "--cells", "16", "--replicas", "2", "--max-steps", "400"], "minimize: 2/2 replicas done"),
    (["dynamics", "--cells", "16", "--replicas", "1", "--steps", "40", "--relax", "30"], "dynamics production: 100%"),
    (["rigidity", "--cells", "16", "--p0", "3.3", "--replicas", "2", "--workers", "1"], "minimisations 2/2"),
])
def test_commands_draw_bars_on_a_terminal_not_in_a_log_and_not_with_quiet(argv, expect, tmp_path, monkeypatch,
                                                                           capsys):
    def run(stderr, *extra):
        if argv[0] == "rigidity":
            argv[argv.index("--out") + 1] = str(tmp_path / f"sweep{run.calls}")
            run.calls += 1
        monkeypatch.setattr(sys, "stderr", stderr)
        assert cli.main(argv + ["--device", "cpu", *extra]) == 0
        return stderr.getvalue()

    run.calls = 0
    if argv[0] == "rigidity":
        argv = argv + ["--out", "", "--no-plots"]
    assert expect in run(Terminal()), "no bar on a terminal"
    log = run(io.StringIO())
    assert expect not in log and "\r" not in log, log     # a log: the start and summary lines only
    assert run(Terminal(), "--quiet") == ""
    capsys.readouterr()


def test_stage_lines_print_a_line_per_stage_and_tenth():
    out = io.StringIO()
    lines = progress.StageLines("N=32", stream=out)
    for done in range(0, 1001, 50):
        lines("production", done, 1000)
    lines("relax", 0, 10)
    text = out.getvalue().splitlines()
    assert len(text) == 12 and text[0].startswith("  N=32 production: 0/1000 steps, ")
    assert text[10].startswith("  N=32 production: 1000/1000 steps") and text[11].startswith("  N=32 relax: 0/10")
