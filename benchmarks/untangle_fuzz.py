"""Crossed cells left by ``T1(untangle=True)`` in hot Brownian dynamics, counted per flip on every
surface by a brute-force checker of its own (docs/validation.md, "Keeping cells simple").

    python benchmarks/untangle_fuzz.py --flips 20000                    # every surface, 20,000 flips each
    python benchmarks/untangle_fuzz.py --surface torus --flips 1000000  # the full count for one surface
    python benchmarks/untangle_fuzz.py --no-revert                      # without the step refusal (flips only)

Each surface: ``--replicas`` random tilings of ``--cells`` cells, Brownian steps (kr = 0, p0 =
3.775, ``--T``, ``--dt``) with ``T1(untangle=True)`` and its
:meth:`~spherevm.plugins.updaters.T1.untangle_pass` after every step: ``--relax`` steps not counted
(the random tilings' many first flips), then until ``--flips`` flips. After every pass
:func:`brute_force_crossings` (not :mod:`spherevm.simplicity`) looks for cells crossing themselves.
Printed per surface: steps, flips, crossed cells the pass met (:func:`brute_force_crossings` before it), crossed cells left after it, steps with any left, the
replica steps the pass refused (went back to what the previous pass left), flips per second, and
(``--classify``) what the crossed cells left were: ``bow tie`` (two edges with one edge between
them cross), ``pinched`` (edges further apart), and for the bow ties whether T1's rules would flip
the middle edge.
"""
import argparse
import datetime
import os
import platform
import time

import numpy as np

import spherevm as svm
from spherevm.constraints import Ellipsoid, GaussianBump, Torus
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import Brownian
from spherevm.plugins.updaters import T1

#: surfaces at sizes valid for dynamics (docs/surfaces.md: a 3:1 torus needs >= 60 cells)
SURFACES = {"sphere": None, "plane": "plane", "torus": lambda: Torus(3.0, 1.0),
            "ellipsoid": lambda: Ellipsoid(1.0, 1.5, 2.0), "bump": lambda: GaussianBump(1.5, 1.0, 10.0)}


def tiling(surface, n_cells, replicas, seed):
    """Random tilings of ``surface`` (a key of :data:`SURFACES`), <A> = 1."""
    if surface == "plane":
        return svm.init.random_planar_tiling(n_cells, replicas=replicas, seed=seed)
    make = SURFACES[surface]
    return svm.init.random_tiling(n_cells, replicas=replicas, seed=seed, surface=None if make is None else make())


def polygons_2d(state):
    """Every cell as a flat polygon ``(C, W, 2)`` (padding repeats the first vertex), from the raw
    arrays: its vertices unwrapped one after another by whole periods (periodic surfaces: the box
    of ``state.size``'s first two columns), then projected along the surface normal at their mean
    (the sphere: gnomonically, so that great circles map to straight lines) onto that tangent plane."""
    pos, cv, sides = (state.device.to_numpy(a) for a in (state.positions, state.cell_vertices, state.cell_sides))
    con = state.constraint
    col = np.arange(cv.shape[1])[None, :]
    ring = pos[np.where(col < sides[:, None], cv, cv[:, :1])]                         # (C, W, 3)
    if getattr(con, "periodic", False) or state.box is not None:
        box = state.device.to_numpy(state.size)[state.cell_replica_np()][:, None, :2]
        step = np.diff(ring[..., :2], axis=1)
        step -= box * np.round(step / box)
        ring = ring.copy()
        ring[:, 1:, :2] = ring[:, :1, :2] + np.cumsum(step, axis=1)
    centre = (ring.sum(axis=1) - ring[:, 0] * (cv.shape[1] - sides)[:, None]) / sides[:, None]
    if state.box is not None:
        normal = np.broadcast_to([0.0, 0.0, 1.0], centre.shape)
    elif state.constraint.__class__.__name__ == "Sphere":
        normal = centre / np.linalg.norm(centre, axis=1)[:, None]
        ring = ring / np.einsum("cwi,ci->cw", ring, normal)[..., None]            # gnomonic
    else:
        size = state.device.to_numpy(state.size)[state.cell_replica_np()]
        normal = con.normal(con.project_normal(centre, size), size)
    e1 = np.cross(normal, np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(normal, e1)
    return np.stack([np.einsum("cwi,ci->cw", ring, e1), np.einsum("cwi,ci->cw", ring, e2)], axis=2)


def brute_force_crossings(state):
    """Cells with two edges that share no vertex and intersect, by solving for the intersection of
    every pair of edges of the flat polygons (:func:`polygons_2d`); a set of (cell, i, j), i < j."""
    poly, sides = polygons_2d(state), state.device.to_numpy(state.cell_sides)
    w = poly.shape[1]
    nxt = (np.arange(w)[None, :] + 1) % sides[:, None]
    d = np.take_along_axis(poly, np.broadcast_to(nxt[..., None], poly.shape), axis=1) - poly
    i, j = np.triu_indices(w, 2)
    pi, pj, di, dj = poly[:, i], poly[:, j], d[:, i], d[:, j]
    cross = lambda a, b: a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]   # noqa: E731
    den = cross(di, dj)
    with np.errstate(divide="ignore", invalid="ignore"):         # parallel edges: den = 0, never a hit
        t, u = cross(pj - pi, dj) / den, cross(pj - pi, di) / den
    real = (j[None, :] < sides[:, None]) & ~((i[None, :] == 0) & (j[None, :] == sides[:, None] - 1))
    hit = real & (den != 0) & (t > 0) & (t < 1) & (u > 0) & (u < 1)
    cells, k = np.nonzero(hit)
    return set(zip(cells.tolist(), i[k].tolist(), j[k].tolist()))


def classify(state, t1, found):
    """Kinds of the crossings ``found`` (:func:`brute_force_crossings`): a dict of counts of cells,
    ``bow tie`` (edges i and i + 2 cross, round the cell) split by whether T1's rules would flip
    the edge between them (``flippable``, else ``refused``), and ``pinched`` (edges further apart)."""
    sides = state.device.to_numpy(state.cell_sides)
    cv = state.device.to_numpy(state.cell_vertices)
    vn = state.device.to_numpy(state.vertex_neighbors)
    out = dict(pinched=0, flippable=0, refused=0)
    for c in sorted({c for c, _, _ in found}):
        pairs = [(i, j) for cc, i, j in found if cc == c]
        n = sides[c]
        bows = [(i, j) for i, j in pairs if (j - i) % n == 2 or (i - j) % n == 2]
        if not bows:
            out["pinched"] += 1
            continue
        i, j = bows[0]
        mid = (i + 1) % n if (j - i) % n == 2 else (j + 1) % n
        u, v = int(cv[c, mid]), int(cv[c, (mid + 1) % n])
        u, v = min(u, v), max(u, v)
        slot = np.array([int(np.flatnonzero(vn[u] == v)[0])])
        uu = np.array([u])
        length = state.device.to_numpy(state.constraint.edge_lengths(state, state.device.xp.asarray(uu),
                                                                    state.vertex_neighbors[uu, slot]))
        flip = t1.select(state, uu, slot, length)[0]
        out["flippable" if flip[0] else "refused"] += 1
    return out


def run(surface, flips, cells=256, replicas=8, T=0.05, dt=0.02, relax=200, seed=0, revert=True, classify_left=False,
        seconds=None, device="cpu"):
    """Hot Brownian dynamics with untangling on ``surface`` until ``flips`` flips (or ``seconds``);
    returns a dict of the counts this script prints."""
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = tiling(surface, cells, replicas, seed)
    sim.operations.forces.append(VertexModel.dimensionless(kr=0.0, p0=3.775))
    t1 = T1(untangle=True)
    sim.operations.updaters.append(t1)
    sim.operations.integrator = Brownian(dt=dt, T=T)
    t1.untangle_pass(sim, revert=revert)         # keeps the tiling's rows: every replica simple
    out = dict(steps=0, flips=0, met=0, left=0, steps_left=0, refused_steps=0, pinched=0, flippable=0, refused=0,
               stopped="", seconds=0.0)
    try:
        for _ in range(relax):                   # the random tilings' first flips: not counted
            sim.run(1)
            t1.untangle_pass(sim, revert=revert)
    except FloatingPointError as err:            # a hot random tiling can blow up: report it, count nothing
        out.update(stopped="while relaxing: " + str(err).split(";")[0], seconds=1.0)
        return out
    start, refused = int(sim.log("t1_total_flips").sum()), int(t1.untangle_refused.sum())
    t0 = time.perf_counter()
    while out["flips"] < flips and (seconds is None or time.perf_counter() - t0 < seconds):
        try:
            sim.run(1)
        except FloatingPointError as err:        # a hot random tiling can blow up: keep what was counted
            out["stopped"] = str(err).split(";")[0]
            break
        out["met"] += len({c for c, _, _ in brute_force_crossings(sim.state)})
        t1.untangle_pass(sim, revert=revert)
        found = brute_force_crossings(sim.state)
        left = len({c for c, _, _ in found})
        out["steps"] += 1
        out["left"] += left
        out["steps_left"] += left > 0
        if left and classify_left:
            for k, n in classify(sim.state, t1, found).items():
                out[k] += n
        out["flips"] = int(sim.log("t1_total_flips").sum()) - start
    out["refused_steps"] = int(t1.untangle_refused.sum()) - refused
    out["seconds"] = time.perf_counter() - t0
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("--surface", nargs="+", default=list(SURFACES), choices=list(SURFACES))
    ap.add_argument("--flips", type=int, default=20000, help="flips per surface (after the relaxation)")
    ap.add_argument("--seconds", type=float, help="stop a surface after this long even if short of --flips")
    ap.add_argument("--cells", type=int, default=256)
    ap.add_argument("--replicas", type=int, default=8)
    ap.add_argument("--T", type=float, default=0.05)
    ap.add_argument("--dt", type=float, default=0.02)
    ap.add_argument("--relax", type=int, default=200, help="steps before the count")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-revert", dest="revert", action="store_false",
                    help="untangle by flips alone (the replica step is never refused)")
    ap.add_argument("--classify", action="store_true", help="classify the crossed cells left")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args(argv)
    print(f"# {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC {platform.machine()} {os.cpu_count()} "
          f"cores, {args.device}, {args.replicas} x {args.cells} cells, kr 0, p0 3.775, T {args.T}, dt {args.dt}, "
          f"revert={args.revert}")
    print(f"{'surface':<9} {'steps':>7} {'flips':>8} {'met':>7} {'left':>5} {'steps w/':>8} {'refused':>7} "
          f"{'pinched':>7} {'bow/flip':>8} {'bow/ref':>7} {'flips/s':>7}")
    for surface in args.surface:
        r = run(surface, args.flips, args.cells, args.replicas, args.T, args.dt, args.relax, args.seed, args.revert,
                args.classify, args.seconds, args.device)
        print(f"{surface:<9} {r['steps']:>7} {r['flips']:>8} {r['met']:>7} {r['left']:>5} {r['steps_left']:>8} "
              f"{r['refused_steps']:>7} {r['pinched']:>7} {r['flippable']:>8} {r['refused']:>7} "
              f"{r['flips'] / r['seconds']:>7.0f}" + (f"  stopped: {r['stopped']}" if r["stopped"] else ""), flush=True)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
