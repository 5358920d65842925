"""The shipped assemblies, made by a script: parametric, deterministic, every part a union of convex bodies.

Three products, each written as a folder of OBJ files (one a part, metres) in its assembled pose:

* :func:`gearbox` — in the spirit of Fox & Kempf's gearbox: a housing (base plate and four walls, two
  bearing bores in each end wall), four flanged bearings in the bores, two shafts through them, a
  pair of meshing gears on the shafts' ends outside the +x end wall (an external gear train, each gear
  slid onto its shaft and seated against its bearing's flange), a cover on the walls and four screws
  through the cover into the end walls.  Under ``--gravity -z`` every part rests on one placed before
  it: the housing on the fixture, the bearings in their bores, the shafts in their bearings, the
  gears on their shafts, the cover on the walls, the screws in their holes.
* :func:`pump` — the centrifugal pump of ``example:pump``: a housing with a stepped bore in its floor,
  a seal on the bore's lip, a bearing on the seal (its flange on the floor), a shaft through them (its
  collar on the flange), a key beside the shaft, an impeller keyed on it (both on the collar), a cover
  and four bolts.  Under ``--gravity -z`` every part rests on one placed before it.
* :func:`puzzle` — two links of a chain threaded through each other on a stand: no sequence builds
  it (``derive`` refuses it, naming the two links).

Rings (bearings, gears, seals) are octagonal, made of eight trapezoid prisms; plates with holes are
cut into boxes.  ``python -m opportune.derive.examples FOLDER`` writes all three (the package ships
them, ``geometry:gearbox``, ``geometry:pump``, ``geometry:puzzle``; a test checks the shipped files
are this script's output).

>>> parts = gearbox()
>>> sorted(parts)[:3], len(parts)
(['bearing_a1', 'bearing_a2', 'bearing_b1'], 14)
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: A convex body: its corners (k × 3, metres) and its faces, each a list of corner indices.
Body = tuple[np.ndarray, list[list[int]]]
#: cos 22.5°: an octagon with flats on the axes has corners at ``apothem / cos 22.5°``.
_OCT = math.cos(math.pi / 8)


def _prism(polygon: list[tuple[float, float]], axis: int, lo: float, hi: float) -> Body:
    """A convex polygon (in the plane across ``axis``: its two other coordinates in order) extruded
    from ``lo`` to ``hi`` along ``axis``."""
    u, v = [a for a in range(3) if a != axis]
    n = len(polygon)
    corners = np.zeros((2 * n, 3))
    for k, (a, b) in enumerate(polygon):
        for layer, h in enumerate((lo, hi)):
            corners[layer * n + k, [u, v, axis]] = (a, b, h)
    faces = [list(range(n)), list(range(n, 2 * n))]
    faces += [[k, (k + 1) % n, n + (k + 1) % n, n + k] for k in range(n)]
    return corners, faces


def box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> Body:
    """An axis-aligned box from corner ``lo`` to corner ``hi``."""
    return _prism([(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])], 2, lo[2], hi[2])


def octagon(centre: tuple[float, float], apothem: float) -> list[tuple[float, float]]:
    """An octagon's corners, counter-clockwise, its flats facing the two axes of the plane."""
    r = apothem / _OCT
    return [(centre[0] + r * math.cos(math.pi / 8 + k * math.pi / 4),
             centre[1] + r * math.sin(math.pi / 8 + k * math.pi / 4)) for k in range(8)]


def ring(centre: tuple[float, float], inner: float, outer: float, axis: int, lo: float, hi: float) -> list[Body]:
    """An octagonal ring (inner and outer apothems) along ``axis``: eight trapezoid prisms."""
    a, b = octagon(centre, inner), octagon(centre, outer)
    return [_prism([a[k], b[k], b[(k + 1) % 8], a[(k + 1) % 8]], axis, lo, hi) for k in range(8)]


def rod(centre: tuple[float, float], apothem: float, axis: int, lo: float, hi: float) -> Body:
    """An octagonal rod along ``axis``."""
    return _prism(octagon(centre, apothem), axis, lo, hi)


def cut(lo: tuple[float, float, float], hi: tuple[float, float, float],
        holes: list[tuple[tuple[float, float, float], tuple[float, float, float]]]) -> list[Body]:
    """The box ``lo``..``hi`` less the boxes ``holes``, as few boxes: the grid of every hole's planes,
    its cells outside the holes merged greedily along x, then y, then z."""
    grid = [sorted({lo[a], hi[a], *(min(max(h[s][a], lo[a]), hi[a]) for h in holes for s in (0, 1))})
            for a in range(3)]
    shape = tuple(len(g) - 1 for g in grid)
    solid = np.ones(shape, bool)
    for h_lo, h_hi in holes:
        mids = [np.array([(g[i] + g[i + 1]) / 2 for i in range(len(g) - 1)]) for g in grid]
        inside = [(m > h_lo[a]) & (m < h_hi[a]) for a, m in enumerate(mids)]
        solid &= ~(inside[0][:, None, None] & inside[1][None, :, None] & inside[2][None, None, :])
    out = []
    for i, j, k in zip(*np.nonzero(solid)):
        if not solid[i, j, k]:
            continue
        i2 = i + 1
        while i2 < shape[0] and solid[i2, j, k]:
            i2 += 1
        j2 = j + 1
        while j2 < shape[1] and solid[i:i2, j2, k].all():
            j2 += 1
        k2 = k + 1
        while k2 < shape[2] and solid[i:i2, j:j2, k2].all():
            k2 += 1
        solid[i:i2, j:j2, k:k2] = False
        out.append(box((grid[0][i], grid[1][j], grid[2][k]), (grid[0][i2], grid[1][j2], grid[2][k2])))
    return out


@dataclass(frozen=True)
class Gearbox:
    """The gearbox's dimensions, metres: the housing's outside, its wall, the two shafts' height and
    places across, the gears' and bearings' apothems (octagons), how far the shafts reach past the
    gears, and the screws."""

    length: float = 0.08        # x: the shafts' direction
    width: float = 0.08         # y
    height: float = 0.05        # z: the walls' top (the cover sits on it)
    wall: float = 0.005
    cover: float = 0.005
    shaft_z: float = 0.028
    shaft_y: tuple[float, float] = (0.025, 0.055)
    shaft: float = 0.004        # apothem
    bearing: float = 0.008      # outer apothem (the bore's half side)
    flange: float = 0.011       # the bearing's flange, outside the wall: its apothem and width
    flange_width: float = 0.002
    gears: tuple[float, float] = (0.012, 0.018)   # apothems: they touch, flat on flat, between the shafts
    gear_width: float = 0.01
    overhang: float = 0.003     # the shafts' ends past the gears' outer faces
    screw: float = 0.003        # the shank's side
    head: float = 0.007         # the head's side
    head_height: float = 0.003
    thread: float = 0.008       # how deep the shank goes into the wall


def gearbox(g: Gearbox = Gearbox()) -> dict[str, list[Body]]:
    """The gearbox's parts by id, each a list of convex bodies (see the module).

    Parameters
    ----------
    g : Gearbox
        The dimensions (the gears' apothems must add up to the shafts' distance).

    Returns
    -------
    dict
        Part id → convex bodies.

    Raises
    ------
    ValueError
        Gears that do not meet between the shafts.

    Examples
    --------
    >>> len(gearbox()["housing"])     # base, two side walls, two end walls cut around bores and screw holes
    19
    """
    if not math.isclose(sum(g.gears), g.shaft_y[1] - g.shaft_y[0]):
        raise ValueError("the gears' apothems must add up to the distance between the shafts")
    L, W, H, t = g.length, g.width, g.height, g.wall
    s = g.screw / 2
    screws = [(x, y) for x in (t / 2, L - t / 2) for y in (0.0125, W - 0.0125)]
    housing = [box((0, 0, 0), (L, W, t)), box((t, 0, t), (L - t, t, H)), box((t, W - t, t), (L - t, W, H))]
    for x0 in (0.0, L - t):
        bores = [((x0, y - g.bearing, g.shaft_z - g.bearing), (x0 + t, y + g.bearing, g.shaft_z + g.bearing))
                 for y in g.shaft_y]
        holes = [((x0, y - s, H - g.thread), (x0 + t, y + s, H)) for x, y in screws if x < x0 + t and x > x0]
        housing += cut((x0, 0, t), (x0 + t, W, H), bores + holes)
    parts = {"housing": housing}
    # the gears outside the +x end wall, seated against the flanges of bearings a2 and b2
    x_gear = L + g.flange_width
    for n, y in zip("ab", g.shaft_y):
        parts[f"shaft_{n}"] = [rod((y, g.shaft_z), g.shaft, 0, -t, x_gear + g.gear_width + g.overhang)]
        for k, x0 in enumerate((0.0, L - t), 1):
            # a bearing in its bore, with a flange on the wall's outside: it goes in from outside only
            out = (x0 - g.flange_width, x0) if k == 1 else (x0 + t, x0 + t + g.flange_width)
            parts[f"bearing_{n}{k}"] = (ring((y, g.shaft_z), g.shaft, g.bearing, 0, x0, x0 + t)
                                        + ring((y, g.shaft_z), g.shaft, g.flange, 0, *out))
    for n, y, apothem in zip("ab", g.shaft_y, g.gears):
        parts[f"gear_{n}"] = ring((y, g.shaft_z), g.shaft, apothem, 0, x_gear, x_gear + g.gear_width)
    parts["cover"] = cut((0, 0, H), (L, W, H + g.cover),
                         [((x - s, y - s, H), (x + s, y + s, H + g.cover)) for x, y in screws])
    for k, (x, y) in enumerate(screws, 1):
        top = H + g.cover
        parts[f"screw_{k}"] = [box((x - s, y - s, H - g.thread), (x + s, y + s, top)),
                               box((x - g.head / 2, y - g.head / 2, top), (x + g.head / 2, y + g.head / 2,
                                                                           top + g.head_height))]
    return parts


def pump() -> dict[str, list[Body]]:
    """The pump's parts by id (see the module): its axis is z, the impeller at the top under the cover.
    The bore in the housing's floor is stepped: the seal sits on its lip, the bearing on the seal with
    its flange on the floor, the shaft's collar on the bearing's flange, and the impeller and the key on
    the collar, so under ``--gravity -z`` every part rests on one below it.

    Returns
    -------
    dict
        Part id → convex bodies.

    Examples
    --------
    >>> sorted(pump())[:4]
    ['bearing', 'bolt_1', 'bolt_2', 'bolt_3']
    """
    L, t, floor, H, lid = 0.07, 0.005, 0.012, 0.04, 0.005
    c, shaft, bore, s, deep = L / 2, 0.004, 0.008, 0.0015, 0.008
    lip, flange, collar = 0.002, floor + 0.003, 0.018      # the lip's top, the flange's top, the collar's top
    bolts = [(x, y) for y in (t / 2, L - t / 2) for x in (0.01, L - 0.01)]
    housing = cut((0, 0, 0), (L, L, floor), [((c - 0.006, c - 0.006, 0), (c + 0.006, c + 0.006, lip)),
                                             ((c - bore, c - bore, lip), (c + bore, c + bore, floor))])
    housing += [box((0, t, floor), (t, L - t, H)), box((L - t, t, floor), (L, L - t, H))]
    for y0 in (0.0, L - t):   # the side walls, with the bolts' blind holes in their tops
        housing += cut((0, y0, floor), (L, y0 + t, H),
                       [((x - s, y - s, H - deep), (x + s, y + s, H)) for x, y in bolts if y0 < y < y0 + t])
    key = ((c + shaft, c - 0.0015, collar), (c + shaft + 0.003, c + 0.0015, 0.03))
    hub = ((c - 0.012, c - 0.012, collar), (c + 0.012, c + 0.012, collar + 0.006))
    # the hub's hole: the square round the shaft's octagon (touching its four flats) and the key's slot
    impeller = cut(*hub, [((c - shaft, c - shaft, hub[0][2]), (c + shaft, c + shaft, hub[1][2])),
                          ((key[0][0], key[0][1], hub[0][2]), (key[1][0], key[1][1], hub[1][2]))])
    z0, z1 = hub[1][2], hub[1][2] + 0.008
    impeller += [box((c + 0.008, c - 0.001, z0), (c + 0.012, c + 0.001, z1)),   # clear of the key
                 box((c - 0.012, c - 0.001, z0), (c - 0.006, c + 0.001, z1)),
                 box((c - 0.001, c + 0.006, z0), (c + 0.001, c + 0.012, z1)),
                 box((c - 0.001, c - 0.012, z0), (c + 0.001, c - 0.006, z1))]
    parts = {"housing": housing,
             "bearing": ring((c, c), shaft, bore, 2, floor / 2, floor) + ring((c, c), shaft, 0.012, 2, floor, flange),
             "seal": ring((c, c), shaft, bore, 2, lip, floor / 2),
             # the collar under the key reaches past it (apothem 0.0075), narrower than the bore
             "shaft": [rod((c, c), shaft, 2, 0.001, 0.03), *ring((c, c), shaft, 0.0075, 2, flange, collar)],
             "key": [box(*key)], "impeller": impeller,
             "cover": cut((0, 0, H), (L, L, H + lid), [((x - s, y - s, H), (x + s, y + s, H + lid)) for x, y in bolts])}
    for k, (x, y) in enumerate(bolts, 1):
        parts[f"bolt_{k}"] = [box((x - s, y - s, H - deep), (x + s, y + s, H + lid)),
                              box((x - 0.003, y - 0.003, H + lid), (x + 0.003, y + 0.003, H + lid + 0.003))]
    return parts


def puzzle() -> dict[str, list[Body]]:
    """Two chain links threaded through each other, on a stand: they lock each other (no straight move
    takes either out of the other), the stand is free.

    Returns
    -------
    dict
        Part id → convex bodies.

    Examples
    --------
    >>> sorted(puzzle())
    ['link_a', 'link_b', 'stand']
    """
    t = 0.004   # the links' bars: square, t thick
    # link_a in the x-z plane; link_b in the y-z plane, its bottom bar through a's hole, a's top bar through its own
    link_a = cut((-0.015, -t / 2, 0.004), (0.015, t / 2, 0.034), [((-0.011, -t / 2, 0.008), (0.011, t / 2, 0.030))])
    link_b = cut((-t / 2, -0.015, 0.016), (t / 2, 0.015, 0.046), [((-t / 2, -0.011, 0.020), (t / 2, 0.011, 0.042))])
    return {"link_a": link_a, "link_b": link_b, "stand": [box((-0.03, -0.03, 0.0), (0.03, 0.03, 0.004))]}


def obj_text(bodies: list[Body]) -> str:
    """The bodies as an OBJ file: each body with its own vertices, its faces (convex polygons) facing out;
    the reader fans them into triangles.

    Parameters
    ----------
    bodies : list
        Convex bodies ``(corners, faces)``.

    Returns
    -------
    str
        The file's text (coordinates to a micrometre).

    Examples
    --------
    >>> print(obj_text([box((0, 0, 0), (1, 1, 1))]).splitlines()[0])
    v 0 0 0
    """
    lines: list[str] = []
    base = 1
    for corners, faces in bodies:
        lines += ["v " + " ".join(f"{round(c, 6) + 0.0:.6g}" for c in p) for p in corners.tolist()]
        centre = corners.mean(axis=0)
        for face in faces:
            pts = corners[face]
            normal = np.cross(pts[1] - pts[0], pts[2] - pts[0])
            if normal @ (pts.mean(axis=0) - centre) < 0:
                face = face[::-1]
            lines.append("f " + " ".join(str(base + k) for k in face))
        base += len(corners)
    return "\n".join(lines) + "\n"


#: The shipped assemblies: name → the function that makes it.
ASSEMBLIES = {"gearbox": gearbox, "pump": pump, "puzzle": puzzle}


def write(name: str, folder: str | Path) -> list[Path]:
    """Write a shipped assembly's parts into ``folder`` (made if missing), one OBJ file a part.

    Parameters
    ----------
    name : str
        ``gearbox``, ``pump`` or ``puzzle``.
    folder : str or Path
        Where to write.

    Returns
    -------
    list of Path
        The files written, sorted.

    Raises
    ------
    KeyError
        An unknown name.

    Examples
    --------
    >>> import tempfile
    >>> [p.name for p in write("puzzle", tempfile.mkdtemp())]
    ['link_a.obj', 'link_b.obj', 'stand.obj']
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for part, bodies in sorted(ASSEMBLIES[name]().items()):
        path = folder / f"{part}.obj"
        path.write_text(f"# {name}: {part} (opportune.derive.examples)\n" + obj_text(bodies), encoding="utf-8")
        out.append(path)
    return out


def looks(plan, seed: int = 0, visible: int = 2) -> list[list[str]]:
    """Looks at a bin for a replay: the parts in a seeded random order, the camera seeing the first ``visible``
    still in it, the paper's rule (exact) choosing each time; the looks it saw, until the product is built.

    Parameters
    ----------
    plan : Plan
        The plan the rule follows.
    seed : int
        Seed of the parts' order in the bin.
    visible : int
        Parts seen per look.

    Returns
    -------
    list of list of str
        One look per decision (an empty look when only the buffer is left to install from).

    Examples
    --------
    >>> from opportune import make_plan
    >>> looks(make_plan(["a", "b"], {"b": ["a"]}), seed=1)
    [['b', 'a'], ['b']]
    """
    import random

    from opportune.sequencer import Sequencer

    bin_ = [p.id for p in plan.parts for _ in range(p.quantity)]
    random.Random(seed).shuffle(bin_)
    seq = Sequencer(plan, budget=None)
    out: list[list[str]] = []
    while True:
        look = bin_[:visible]
        decision = seq.decide(visible=look)
        if decision.action.kind == "done":
            return out
        out.append(look)
        if decision.action.kind in ("install", "buffer") and decision.action.source != "buffer":
            bin_.remove(decision.action.part)
        seq.report("success")


def looks_text(name: str, plan, seed: int = 0, options: str = "") -> str:
    """A looks file for a shipped assembly's derived plan (see :func:`looks`), one look a line; ``options``
    are those the plan was derived with, as the file's header states them."""
    rows = looks(plan, seed)
    return (f"# Looks at a bin of the {name} derived from its meshes (opportune derive geometry:{name}{options}): the\n"
            f"# parts in a random order (seed {seed}), the camera seeing two; `opportune replay` replays them.\n"
            + "\n".join(" ".join(r) or "-" for r in rows) + "\n")


if __name__ == "__main__":   # python -m opportune.derive.examples FOLDER: the shipped assemblies, one folder each
    for shipped in ASSEMBLIES:
        write(shipped, Path(sys.argv[1]) / shipped)
    from opportune.derive import derive

    # the looks of the realistic setting: each part rests on what is below it
    (Path(sys.argv[1]).parent / "gearbox-meshes.looks").write_text(
        looks_text("gearbox", derive(Path(sys.argv[1]) / "gearbox", gravity="-z").plan, options=" --gravity -z"),
        encoding="utf-8")
