"""Ctrl-C (issue 13, item 9): during start-up and while a sweep's workers run, the ``spherevm``
command ends promptly with one line and exit status 130, and leaves no worker behind."""
import multiprocessing
import os
import signal
import subprocess
import sys
import time

import pytest

from spherevm import cli


def _env():
    return dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))


def test_importing_the_command_line_is_light():
    """Start-up work (NumPy, the subcommands) happens inside main, where Ctrl-C is caught."""
    code = "import sys, spherevm, spherevm.cli; print(sorted(m for m in ('numpy', 'scipy', 'spherevm.init') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env())
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


def test_ctrl_c_while_starting_is_one_line(monkeypatch, capsys):
    real = cli.importlib.import_module

    def interrupted(name, package=None):
        if name == ".rigidity":
            raise KeyboardInterrupt   # as if Ctrl-C came while the subcommands are imported
        return real(name, package)

    monkeypatch.setattr(cli.importlib, "import_module", interrupted)
    assert cli.main(["info"]) == 130
    err = capsys.readouterr().err
    assert err.strip() == "spherevm: interrupted" and "Traceback" not in err


def _descendants(pid):
    """Process ids descending from ``pid`` (Linux /proc): the pool's workers are its children, or
    the children of the fork server it started."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parents[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                pass
    out, frontier = [], [pid]
    while frontier:
        frontier = [child for child, parent in parents.items() if parent in frontier]
        out += frontier
    return out


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs Linux /proc to find the workers")
def test_sigint_to_the_main_process_alone_stops_a_sweep_at_once(tmp_path):
    """The workers are terminated rather than left to finish their chunks (11 s to minutes before)."""
    proc = subprocess.Popen([sys.executable, "-m", "spherevm", "rigidity", "--cells", "64", "128", "--replicas", "8",
                             "--device", "cpu", "-j", "2", "--no-plots", "--out", str(tmp_path / "sweep")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    # the two workers, multiprocessing's resource tracker and, where the pools fork from one, the fork server
    expected = 4 if "forkserver" in multiprocessing.get_all_start_methods() else 3
    deadline = time.monotonic() + 60
    while len(_descendants(proc.pid)) < expected and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    workers = _descendants(proc.pid)
    time.sleep(2.0)                       # the workers have started their chunks (tens of seconds each)
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - start
    assert proc.returncode == 130, err
    assert took < 5, took
    assert err.strip().splitlines()[-1] == "spherevm: interrupted" and "Traceback" not in err, err
    assert len(workers) >= expected
    deadline = time.monotonic() + 5
    while any(_state(w) not in ("gone", "Z") for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert all(_state(w) in ("gone", "Z") for w in workers), [(w, _state(w)) for w in workers]


def _state(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"
