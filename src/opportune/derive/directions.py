"""The insertion directions of a derivation, and the supports each part needs (``--gravity``, ``--connected``).

Directions are named as ``--directions`` takes them: an axis by its name (``+x`` … ``-z``, moving
along it into place), any other direction by its unit vector's three coordinates (``0 0.707107
0.707107``).  The default set is the six axes plus the normals of the contacts between parts, both
ways: where a part's blockers change (Wilson and Latombe's non-directional blocking graph changes
only at such directions among the contacts', for polyhedra sliding along their faces).
"""

from __future__ import annotations

import numpy as np

from opportune.derive.blocking import AXES
from opportune.derive.contacts import UPWARD, Contact
from opportune.derive.geometry import Assembly, GeometryError
from opportune.derive.plan import Conditions
from opportune.limits import MAX_DIRECTIONS

#: Decimals of a direction's name (and two directions closer than this are one).
DECIMALS = 6


def parse_directions(spec: str) -> dict[str, tuple[float, float, float]]:
    """The directions a ``--directions`` text names: ``axes``, axis names and vectors, separated by commas.

    Parameters
    ----------
    spec : str
        E.g. ``"axes"``, ``"+z,-x"`` or ``"+z,0 0.7 0.7"`` (a vector is three numbers; it is normalised).

    Returns
    -------
    dict
        Names (as :func:`direction_name` gives them) and unit vectors, each direction once.

    Raises
    ------
    GeometryError
        An item that is neither ``axes``, an axis name nor three finite numbers not all zero, or more than
        :data:`~opportune.limits.MAX_DIRECTIONS` directions.

    Examples
    --------
    >>> list(parse_directions("+z, 0 0.7 0.7, -x"))
    ['+z', '0 0.707107 0.707107', '-x']
    >>> parse_directions("up")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: directions: 'up' is not a direction; give axes, an axis (+x, -x, +y, -y, +z, -z) or three numbers such as '0 0.7 0.7', separated by commas
    """
    if len(spec) > 20 * MAX_DIRECTIONS + 100:
        raise GeometryError(f"directions: {len(spec):,} characters; give at most {MAX_DIRECTIONS} directions")
    out: dict[str, tuple[float, float, float]] = {}
    for item in (x.strip() for x in spec.split(",")):
        vectors = list(AXES.values()) if item == "axes" else [_vector(item)]
        for v in vectors:
            out.setdefault(direction_name(v), _unit(v))
    if len(out) > MAX_DIRECTIONS:
        raise GeometryError(f"directions: {len(out)} directions; give at most {MAX_DIRECTIONS}")
    return out


def _vector(item: str) -> tuple[float, float, float]:
    if item in AXES:
        return AXES[item]
    words = item.split()
    try:
        v = tuple(float(w) for w in words)
    except ValueError:
        v = ()
    if len(v) != 3 or not all(np.isfinite(v)) or not any(v):
        shown = item if len(item) <= 40 else item[:40] + "…"
        raise GeometryError(f"directions: {shown!r} is not a direction; give axes, an axis ({', '.join(AXES)}) or "
                            "three numbers such as '0 0.7 0.7', separated by commas")
    return v


def _unit(v) -> tuple[float, float, float]:
    u = np.asarray(v, float) / np.linalg.norm(v)
    return tuple(float(x) for x in np.round(u, DECIMALS) + 0.0)


def direction_name(v) -> str:
    """A direction's name: its axis's (``+x``), or its unit vector's coordinates to :data:`DECIMALS` places.

    Parameters
    ----------
    v : sequence of float
        A vector, not zero.

    Returns
    -------
    str
        The name.

    Examples
    --------
    >>> direction_name((0, 0, -2)), direction_name((0, 1, 1))
    ('-z', '0 0.707107 0.707107')
    """
    u = _unit(v)
    for name, axis in AXES.items():
        if u == tuple(float(x) for x in axis):
            return name
    return " ".join(f"{x:.{DECIMALS}f}".rstrip("0").rstrip(".") for x in u)


def default_directions(contacts: list[Contact]) -> dict[str, tuple[float, float, float]]:
    """The six axes and the contacts' normals, both ways (the default ``--directions``).

    Parameters
    ----------
    contacts : list of Contact
        The assembly's contacts (:func:`opportune.derive.contacts.find_contacts`).

    Returns
    -------
    dict
        Names and unit vectors, the axes first.

    Raises
    ------
    GeometryError
        More than :data:`~opportune.limits.MAX_DIRECTIONS` directions: give ``--directions``.

    Examples
    --------
    >>> list(default_directions([Contact("a", "b", (0.0, 0.6, 0.8), 1.0)]))[6:]
    ['0 0.6 0.8', '0 -0.6 -0.8']
    """
    out = {name: tuple(float(x) for x in v) for name, v in AXES.items()}
    for c in contacts:
        for v in (c.normal, tuple(-x for x in c.normal)):
            out.setdefault(direction_name(v), _unit(v))
    if len(out) > MAX_DIRECTIONS:
        raise GeometryError(f"the axes and the contacts' normals make {len(out)} directions; at most "
                            f"{MAX_DIRECTIONS} are examined: give --directions (axes, or a list)")
    return out


def support_conditions(assembly: Assembly, contacts: list[Contact], *, gravity: str | None = None,
                       connected: bool = False, base: str | None = None) -> Conditions:
    """What each part needs in before it: with ``gravity``, a part it rests on (touching it from above)
    unless it rests on the fixture (its lowest point at the assembly's lowest level: the first part too
    must), with ``connected``, a part it touches (unless it is the first); the ``base`` first, held by
    the fixture.

    Parameters
    ----------
    assembly : Assembly
        The parts.
    contacts : list of Contact
        Their contacts.
    gravity : str, optional
        The direction of gravity (as ``--directions`` names one: ``-z``, or three numbers).
    connected : bool
        Each part after the first touches a part in before it.
    base : str, optional
        The part that goes first.

    Returns
    -------
    Conditions
        The requirements of each part and the base.

    Raises
    ------
    GeometryError
        A base that is not a part, or a gravity that is not one direction.

    Examples
    --------
    >>> c = [Contact("floor", "top", (0.0, 0.0, 1.0), 1.0), Contact("floor", "side", (1.0, 0.0, 0.0), 1.0)]
    >>> from opportune.derive.geometry import Assembly, Body, PartShape
    >>> def part(name, z):
    ...     v = np.array([[i, j, z + k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    ...     return PartShape(name, None, (Body(v, np.eye(3), np.eye(3)),), 12)
    >>> a = Assembly((part("floor", 0), part("side", 0), part("top", 1)), 1e-9, "m")
    >>> support_conditions(a, c, gravity="-z").needs      # side and floor stand on the fixture
    {'top': (('gravity', frozenset({'floor'})),)}
    """
    ids = {p.id for p in assembly.parts}
    if base is not None and base not in ids:
        raise GeometryError(f"base {base!r} is not a part; the parts are the files' stems: "
                            + ", ".join(sorted(ids)[:10]) + (", …" if len(ids) > 10 else ""))
    needs: dict[str, list[tuple[str, frozenset[str]]]] = {p: [] for p in sorted(ids)}
    if gravity is not None:
        down = parse_directions(gravity)
        if len(down) != 1:
            raise GeometryError(f"gravity {gravity!r}: give one direction, such as -z")
        up = -np.asarray(next(iter(down.values())))
        lowest = {p.id: min(float((b.vertices @ up).min()) for b in p.bodies) for p in assembly.parts}
        floor = min(lowest.values())
        on = {p: set() for p in ids}
        for c in contacts:
            lift = float(np.dot(c.normal, up))
            if lift > UPWARD:
                on[c.b].add(c.a)
            elif lift < -UPWARD:
                on[c.a].add(c.b)
        for p in sorted(ids):
            if lowest[p] > floor + assembly.tolerance:
                needs[p].append(("gravity", frozenset(on[p])))
    if connected:
        touching = {p: set() for p in ids}
        for c in contacts:
            touching[c.a].add(c.b)
            touching[c.b].add(c.a)
        for p in sorted(ids):
            needs[p].append(("connected", frozenset(touching[p])))
    # the first part rests on the fixture (gravity holds for it too) but touches nothing built yet
    return Conditions({p: tuple(n) for p, n in needs.items() if n}, base, frozenset({"connected"}))
