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


# ------------------------------------------------------------------------ the docs as a manual
DIARY = re.compile(r"\bsession\s+\d+", re.I)


def test_no_development_diary_in_docs_or_code():
    """The development history stays in the git log: no "session N" in the docs, the package, the
    benchmarks or the examples."""
    found = []
    for folder in ("docs", "spherevm", "benchmarks", "examples"):
        for path in sorted((ROOT / folder).rglob("*")):
            if path.suffix not in (".md", ".py", ".cu", ".cuh", ".ipynb", ".rst") or not path.is_file():
                continue
            for n, line in enumerate(path.read_text().splitlines(), 1):
                if DIARY.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()[:80]}")
    assert not found, "state the fact, not the session it came from:\n" + "\n".join(found)


def test_index_links_every_page():
    text = (ROOT / "docs" / "index.md").read_text()
    missing = [p.name for p in sorted((ROOT / "docs").glob("*.md"))
               if p.name != "index.md" and f"]({p.name})" not in text]
    assert not missing, f"docs/index.md's table of pages does not link {missing}"


def _sections(text):
    """{heading: body} of a page's level-2 sections."""
    parts = re.split(r"^## (.*)$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def _cli_subparsers():
    import argparse
    from spherevm.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, sub.choices


def test_cli_md_documents_every_command_and_option():
    """Every subcommand has a section "## `spherevm NAME`" in docs/cli.md that names each of its
    options (every spelling: `--cells` and `-N`); the top-level options appear on the page."""
    text = (ROOT / "docs" / "cli.md").read_text()
    sections = _sections(text)
    parser, commands = _cli_subparsers()
    missing = []
    for option in (s for a in parser._actions for s in a.option_strings if s not in ("-h", "--help")):
        if not re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", text):
            missing.append(f"spherevm {option}")
    for name, sub in commands.items():
        body = sections.get(f"`spherevm {name}`")
        if body is None:
            missing.append(f"the section ## `spherevm {name}`")
            continue
        for action in sub._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help") and not re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", body):
                    missing.append(f"spherevm {name} {option}")
    assert not missing, f"docs/cli.md does not document: {missing}"


def test_architecture_md_layers_are_test_layers_table():
    """docs/architecture.md's layer table lists the layers of tests/test_layers.py, module for module."""
    from test_layers import LAYERS
    text = (ROOT / "docs" / "architecture.md").read_text()
    rows = re.findall(r"^\| (\d+) [^|]*\| ([^|]*) \|", text, re.M)
    documented = [sorted(re.sub(r"(\.py|/)$", "", m) for m in re.findall(r"`([^`]+)`", modules))
                  for _, modules in rows]
    assert [int(n) for n, _ in rows] == list(range(len(rows)))
    assert documented == [sorted(layer) for layer in LAYERS]
