"""Hand-rolled mutation testing: one small mutation at a time, run the given tests, count kills.

    python3 benchmarks/mutate.py spherevm/plugins/integrators/fire.py \
        tests/test_fire.py tests/test_fire_known_answers.py

Mutations (each applied alone, found with ``ast``): arithmetic operators (+ - * / ** //),
comparisons (< <= > >= == != and ``is``/``is not``, ``in``/``not in``), ``and``/``or``, a dropped
``not`` or unary minus, ``True``/``False``, and numeric constants (0 -> 1, 1 -> 2, x -> x + 1 for
other ints, x -> 1.5 x for floats). Docstrings and other strings are left alone.

The repository is copied to a temporary folder and mutated there, so the working tree is never
touched. The tests are run once unmutated first and must pass. A mutant is killed when the tests
fail (or run past ``--timeout`` seconds). Survivors are
listed with their line and the mutation, to be killed with a test or judged harmless by hand.
``--only 3,17`` runs those mutants (numbered as printed), ``--lines 15,197-300`` the sites on those
lines; ``--jobs N`` runs N mutants at once, each in its own copy (on a machine with cores to spare).
"""
import argparse
import ast
import os
import shutil
import subprocess
import sys
import queue
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

SWAP_BIN = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult,
            ast.Pow: ast.Mult, ast.FloorDiv: ast.Mult, ast.Mod: ast.FloorDiv,
            ast.BitXor: ast.BitOr, ast.BitOr: ast.BitAnd, ast.BitAnd: ast.BitOr,
            ast.LShift: ast.RShift, ast.RShift: ast.LShift}
SWAP_CMP = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt, ast.Eq: ast.NotEq,
            ast.NotEq: ast.Eq, ast.Is: ast.IsNot, ast.IsNot: ast.Is, ast.In: ast.NotIn, ast.NotIn: ast.In}


def _docstring_ids(tree):
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def sites(tree):
    """(index of the node in ast.walk order, description, function applying the mutation)."""
    out = []
    for i, node in enumerate(ast.walk(tree)):
        line = getattr(node, "lineno", "?")
        if isinstance(node, (ast.BinOp, ast.AugAssign)) and type(node.op) in SWAP_BIN:
            new = SWAP_BIN[type(node.op)]
            out.append((i, f"line {line}: {type(node.op).__name__} -> {new.__name__}",
                        lambda n, new=new: setattr(n, "op", new())))
        elif isinstance(node, ast.Compare):
            for k, op in enumerate(node.ops):
                if type(op) in SWAP_CMP:
                    new = SWAP_CMP[type(op)]
                    def f(n, k=k, new=new):
                        n.ops[k] = new()
                    out.append((i, f"line {line}: {type(op).__name__} -> {new.__name__}", f))
        elif isinstance(node, ast.BoolOp):
            new = ast.Or if isinstance(node.op, ast.And) else ast.And
            out.append((i, f"line {line}: {type(node.op).__name__} -> {new.__name__}",
                        lambda n, new=new: setattr(n, "op", new())))
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.Not, ast.USub)):
            out.append((i, f"line {line}: drop {type(node.op).__name__}", "unwrap"))
        elif isinstance(node, ast.Constant) and type(node.value) in (bool, int, float):
            v = node.value
            if isinstance(v, bool):
                new = not v
            elif isinstance(v, int):
                new = 1 if v == 0 else (2 if v == 1 else v + 1)
            else:
                new = 1.0 if v == 0.0 else 1.5 * v
            out.append((i, f"line {line}: {v!r} -> {new!r}",
                        lambda n, new=new: setattr(n, "value", new)))
    return out


def mutant_source(source, index, how):
    tree = ast.parse(source)
    nodes = list(ast.walk(tree))
    node = nodes[index]
    if how == "unwrap":  # replace the UnaryOp by its operand in its parent
        for parent in nodes:
            for field, value in ast.iter_fields(parent):
                if value is node:
                    setattr(parent, field, node.operand)
                elif isinstance(value, list):
                    for j, item in enumerate(value):
                        if item is node:
                            value[j] = node.operand
    else:
        how(node)
    return ast.unparse(ast.fix_missing_locations(tree))


def main(argv=None):
    p = argparse.ArgumentParser(allow_abbrev=False, description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("module", help="path of the module to mutate, relative to the repository root")
    p.add_argument("tests", nargs="+", help="test files to run against each mutant")
    p.add_argument("--timeout", type=float, default=120.0)
    p.add_argument("--only", type=str, default=None, help="comma-separated mutant numbers to run")
    p.add_argument("--lines", type=str, default=None,
                   help="run only the sites on these source lines, e.g. 15,197-300 (numbers stay those of all sites)")
    p.add_argument("--jobs", type=int, default=1, help="mutants run at once, each in its own copy")
    args = p.parse_args(argv)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    source = open(os.path.join(root, args.module)).read()
    tree = ast.parse(source)
    doc = _docstring_ids(tree)
    all_sites = [s for s in sites(tree) if id(list(ast.walk(tree))[s[0]]) not in doc]
    only = None if args.only is None else {int(k) for k in args.only.split(",")}
    lines = None if args.lines is None else _line_set(args.lines)
    nodes = list(ast.walk(tree))
    todo = [(k, site) for k, site in enumerate(all_sites) if (only is None or k in only)
            and (lines is None or getattr(nodes[site[0]], "lineno", None) in lines)]
    copies = queue.Queue()
    try:
        for _ in range(max(1, min(args.jobs, len(todo)))):
            copies.put(_work_copy(root))
        cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *args.tests]
        work = copies.queue[0]
        env = _env(work)
        rc = subprocess.run(cmd, cwd=work, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode
        if rc != 0:   # a kill means something only if the tests pass without a mutation
            sys.exit(f"the tests fail (rc={rc}) on the unmutated module: fix that first: {' '.join(cmd[1:])}")

        def run(item):
            k, (index, desc, how) = item
            work = copies.get()
            try:
                with open(os.path.join(work, args.module), "w") as fh:
                    fh.write(mutant_source(source, index, how))
                env = _env(work)
                t0 = time.time()
                try:
                    rc = subprocess.run(cmd, cwd=work, env=env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL, timeout=args.timeout).returncode
                except subprocess.TimeoutExpired:
                    rc = "timeout"
                with open(os.path.join(work, args.module), "w") as fh:
                    fh.write(source)
            finally:
                copies.put(work)
            print(f"[{k:3d}] {'survived' if rc == 0 else 'killed':8s} {desc}  ({time.time() - t0:.1f}s, rc={rc})",
                  flush=True)
            return k, desc, rc

        with ThreadPoolExecutor(max_workers=copies.qsize()) as pool:
            results = sorted(pool.map(run, todo))
        survived = [(k, desc) for k, desc, rc in results if rc == 0]
        print(f"\n{args.module}: {len(results)} mutants, {len(results) - len(survived)} killed, "
              f"{len(survived)} survived")
        for k, desc in survived:
            print(f"  survivor [{k}] {desc}")
    finally:
        while not copies.empty():
            shutil.rmtree(copies.get(), ignore_errors=True)


def _env(work):
    """The tests' environment: the mutated copy first on the path, then what the caller's path holds
    (dependencies installed into a folder, as on the GPU machine)."""
    path = os.pathsep.join(p for p in (work, os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, PYTHONPATH=path, PYTHONDONTWRITEBYTECODE="1")


def _line_set(text):
    """``"15,197-300"`` -> the set of those line numbers."""
    out = set()
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out.update(range(int(lo), int(hi or lo) + 1))
    return out


def _work_copy(root):
    """A temporary copy of the package and its tests, to mutate without touching the working tree."""
    work = tempfile.mkdtemp(prefix="mutate-")
    for name in ("spherevm", "tests"):
        shutil.copytree(os.path.join(root, name), os.path.join(work, name),
                        ignore=shutil.ignore_patterns("__pycache__", "*.so", "build"))
    shutil.copy(os.path.join(root, "pyproject.toml"), work)
    return work


if __name__ == "__main__":
    main()
