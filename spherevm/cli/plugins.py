"""``spherevm plugins``: the table of :func:`spherevm.plugins.describe`."""
from __future__ import annotations

from .. import plugins


def add_parser(subparsers):
    """Register ``plugins`` on the ``spherevm`` subparsers."""
    p = subparsers.add_parser("plugins", help="list the available plugins (built-in and entry points)",
                              description="List every plugin by name: the built-ins and those registered by "
                                          "installed packages under the entry-point group 'spherevm.plugins'.")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """The handler of ``spherevm plugins``: name, kind and source, one plugin a line."""
    rows = [("name", "kind", "source")] + plugins.describe()
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows if not r[1].startswith("broken"))
    for name, kind, source in rows:
        print(f"{name.ljust(w0)}  {kind.ljust(w1)}  {source}".rstrip())
        if kind == "force":                  # constructor parameters (what --force NAME:k=v takes)
            print(f"{''.ljust(w0)}  {''.ljust(w1)}  parameters: {plugins.parameters_of(plugins.load(name))}")
    return 0
