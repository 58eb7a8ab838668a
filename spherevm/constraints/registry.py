"""Surfaces by name: the built-in ones and those other packages register under the entry-point
group ``spherevm.surfaces``, and the ``name:key=value,...`` specs the command line takes
(``torus:R=3,r=1``)."""
from __future__ import annotations

from importlib.metadata import entry_points

from .bump import GaussianBump
from .ellipsoid import Ellipsoid
from .plane import PeriodicPlane
from .sphere import Sphere
from .torus import Torus

SURFACE_GROUP = "spherevm.surfaces"
BUILTIN = {"sphere": Sphere, "plane": PeriodicPlane, "torus": Torus, "ellipsoid": Ellipsoid, "bump": GaussianBump}
#: short names of constructor arguments in a spec
ALIASES = {"torus": {"R": "major_radius", "r": "minor_radius"}, "bump": {"h": "height", "w": "width"}}


def surfaces() -> dict:
    """Every surface class by name: the built-ins, then the entry points of ``spherevm.surfaces``."""
    found = dict(BUILTIN)
    for ep in entry_points(group=SURFACE_GROUP):
        found.setdefault(ep.name, ep)
    return found


def surface_class(name: str):
    """The surface class of that name (a built-in, or an entry point's, loaded), or None."""
    found = surfaces().get(name)
    return found if found is None or isinstance(found, type) else found.load()


def surface(spec: str):
    """The surface a spec names: ``"torus"``, ``"torus:R=3,r=1"``, ``"ellipsoid:a=1,b=1,c=2"``,
    ``"bump:height=1,width=1"`` or a registered name with its constructor's keywords (numbers).
    ValueError naming the spec's bad part."""
    name, _, rest = str(spec).partition(":")
    known = surfaces()
    if name not in known:
        raise ValueError(f"unknown surface {name!r} in {spec!r}; known: {', '.join(sorted(known))}")
    cls = surface_class(name)
    kwargs = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        try:
            kwargs[ALIASES.get(name, {}).get(key.strip(), key.strip())] = float(value)
        except ValueError:
            raise ValueError(f"surface {spec!r}: {item!r} must be key=number") from None
        if not eq:
            raise ValueError(f"surface {spec!r}: {item!r} must be key=number")
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ValueError(f"surface {spec!r}: {exc}") from None
