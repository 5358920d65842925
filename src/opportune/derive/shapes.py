"""The parts' shapes a derived plan carries: each part's convex bodies, as ``geometry: {convex: ...}``.

The physical bin (``simulate --bin physics``) heaps these shapes instead of boxes.  Each body is
written as its corners in the assembled pose, in metres rounded to :data:`ROUND` (a micrometre);
the bin takes each body's convex hull, which is the body itself for a convex body.  A body that is
not convex (a U, a cup written as one surface) is written as its convex pieces
(:func:`~opportune.derive.solids.convex_pieces`: cut along its own faces' planes, their union the body
exactly), so that a peg can lie in its slot; one that needs more pieces than the part's shape has
bodies left (a curved surface) is written as its hull, said in a note.  The plan's bounds on shapes (:mod:`opportune.formats.shapes`) hold for what is written: a
body with more corners than a body may have keeps its extreme corners along :data:`MAX_BODY_POINTS`
directions spread over the sphere (a slightly smaller hull); a part over the other bounds (too large
or too small for the bin, too many bodies, a flat body, far from the origin) gets no shape, and
more corners in all than a plan holds gives no part one: each omission is said in a note.
"""

from __future__ import annotations

import numpy as np

from opportune.derive.geometry import Assembly, PartShape
from opportune.formats.shapes import COORDINATE, THICKNESS, thickness
from opportune.limits import MAX_BODY_POINTS, MAX_SHAPE_BODIES, MAX_SHAPE_POINTS
from opportune.planning.plan import MAX_DIMENSION, MIN_DIMENSION

#: Metres the written corners are rounded to.
ROUND = 6


def shapes(assembly: Assembly) -> tuple[dict[str, dict], list[str]]:
    """Each part's shape as a plan writes it, and notes on the parts left without one.

    Parameters
    ----------
    assembly : Assembly
        The parts, read from the meshes.

    Returns
    -------
    tuple
        ``({part: {"convex": [[[x, y, z], ...], ...]}}, notes)``.

    Examples
    --------
    >>> from opportune.derive.geometry import read_assembly
    >>> from opportune.formats.shipped import geometry_path
    >>> got, notes = shapes(read_assembly(geometry_path("puzzle")))
    >>> sorted(got), notes
    (['link_a', 'link_b', 'stand'], [])
    """
    out, notes = {}, []
    for part in assembly.parts:
        shape, why = _shape(part)
        if shape is None:
            notes.append(f"part {part.id!r} is heaped as the default box: {why}")
        else:
            out[part.id] = shape
            notes += [f"part {part.id!r}: {why}"] if why else []
    total = sum(len(b) for s in out.values() for b in s["convex"])
    if total > MAX_SHAPE_POINTS:
        return {}, [f"no part's shape written: {total:,} corners in all, over the {MAX_SHAPE_POINTS:,} a plan "
                    "holds (simplify the meshes)"]
    return out, notes


def _shape(part: PartShape) -> tuple[dict | None, str]:
    """One part's shape, or None and why not (with a shape: what it leaves out, if anything)."""
    if len(part.bodies) > MAX_SHAPE_BODIES:
        return None, f"{len(part.bodies)} convex bodies, over the {MAX_SHAPE_BODIES} a shape holds"
    lo, hi = part.bounds
    extent = float((hi - lo).max())
    if not MIN_DIMENSION <= extent <= MAX_DIMENSION:
        return None, f"{extent:.3g} m long, outside {MIN_DIMENSION:g} to {MAX_DIMENSION:g} m"
    if max(float(np.abs(lo).max()), float(np.abs(hi).max())) > COORDINATE:
        return None, f"further than {COORDINATE:g} m from the origin"
    bodies = []
    pieces, hulled = _pieces(part)
    for points in pieces:
        corners = np.round(_fewer(points), ROUND)
        if thickness(corners) < THICKNESS:
            return None, f"a body thinner than {THICKNESS:g} m"
        bodies.append([[_short(c) for c in p] for p in corners.tolist()])
    if len(bodies) > MAX_SHAPE_BODIES:
        return None, f"{len(bodies)} convex bodies, over the {MAX_SHAPE_BODIES} a shape holds"
    why = (f"bod{'ies' if len(hulled) > 1 else 'y'} {', '.join(map(str, hulled))} (not convex) heaped as "
           f"{'their hulls' if len(hulled) > 1 else 'its hull'}: more convex pieces than the {MAX_SHAPE_BODIES} "
           "bodies a shape holds" if hulled else "")
    return {"convex": bodies}, why


def _pieces(part: PartShape) -> tuple[list[np.ndarray], list[int]]:
    """The corners of the part's convex bodies (each convex body's, and each piece of one that is not), and
    the bodies (from 1) written as their hulls: the pieces would take more bodies than the shape has left."""
    from opportune.derive.solids import convex_pieces

    out: list[np.ndarray] = []
    hulled = []
    for k, body in enumerate(part.bodies):
        left = MAX_SHAPE_BODIES - len(out) - (len(part.bodies) - k - 1)
        pieces = None if body.convex else convex_pieces(body, left)
        if pieces is None and not body.convex:
            hulled.append(k + 1)
        out += [body.vertices] if pieces is None else pieces
    return out, hulled


def _fewer(points: np.ndarray) -> np.ndarray:
    """At most :data:`MAX_BODY_POINTS` of a convex body's corners: the extreme ones along as many directions
    spread evenly over the sphere (a Fibonacci lattice), when it has more."""
    if len(points) <= MAX_BODY_POINTS:
        return points
    k = np.arange(MAX_BODY_POINTS) + 0.5
    z = 1 - 2 * k / MAX_BODY_POINTS
    phi = np.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z * z)
    directions = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    keep = np.unique(np.argmax(points @ directions.T, axis=0))
    return points[keep]


def _short(c: float) -> int | float:
    """A coordinate as the file writes it: 0.05, not 0.05000000000000001; 0, not -0.0."""
    c = round(c, ROUND) + 0.0
    return int(c) if c.is_integer() else c
