"""Docs that run: the ```python blocks of README.md and docs/*.md are executed, a page's blocks in
order in one namespace (a page is read top to bottom: later blocks use ``sim`` or ``svm`` from
earlier ones), in a temporary folder, with ``tests/plugin_example`` on the path. A block preceded by
``<!-- no-test: why -->`` is left out (a fragment that cannot run: keep these rare, say why).
"""
import os
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
FILES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
BLOCK = re.compile(r"(?:(<!--[^\n]*-->)\s*\n)?```python\n(.*?)```", re.S)
# pages that need an optional package: page -> module (skipped, with the reason, where it is missing)
NEEDS = {"visualisation.md": "ovito", "rigidity.md": "distributed"}   # optional extras a page uses
RUNNER = """
import sys, traceback
blocks = eval(sys.stdin.read())
ns = {"__name__": "__main__"}
for line, code in blocks:
    try:
        exec(compile(code, f"block at line {line}", "exec"), ns)
    except BaseException:
        traceback.print_exc()
        sys.exit(f"block at line {line} failed")
"""


def page_blocks(path):
    text = path.read_text()
    out = []
    for m in BLOCK.finditer(text):
        if "no-test" not in (m.group(1) or ""):
            out.append((text[:m.start(2)].count("\n") + 1, m.group(2)))
    return out


def pages():
    for path in FILES:
        if not page_blocks(path):
            continue
        yield pytest.param(path, id=str(path.relative_to(ROOT)))


@pytest.mark.parametrize("path", list(pages()))
def test_page_runs(path, tmp_path):
    if path.name in NEEDS:
        pytest.importorskip(NEEDS[path.name])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests" / "plugin_example"),
                                                      os.environ.get("PYTHONPATH", "")]), MPLBACKEND="Agg")
    result = subprocess.run([sys.executable, "-c", RUNNER], input=repr(page_blocks(path)), cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, f"{path.name}: {result.stderr[-3000:]}"


def cli_errors():
    text = (ROOT / "docs" / "cli.md").read_text()
    pairs = re.findall(r"^\$ (spherevm [^\n]*)\n(spherevm: error: [^\n]*)$", text, re.M)
    assert pairs, "docs/cli.md shows no failing command with its 'spherevm: error:' line"
    return pairs


@pytest.mark.parametrize("command,expected", cli_errors())
def test_cli_md_error_text_is_the_real_one(command, expected, tmp_path):
    """docs/cli.md shows failing commands and their messages: run each and compare."""
    if "--device gpu" in command:
        import spherevm
        if spherevm.device.gpu_available():
            pytest.skip("the GPU is usable here, so the documented failure does not happen")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    result = subprocess.run([sys.executable, "-m", "spherevm"] + command.split()[1:], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr.strip() == expected
