"""Which parts block a part's straight insertion along each direction.

The motion model: a part goes in by one straight translation from far away, along one direction of a
set; it may slide along faces it touches but never pass through another part's interior.  A part
``p`` inserted along ``d`` (moving along ``d`` into place, from far away on the ``-d`` side) sweeps
``p ⊕ {-t·d : t ≥ 0}``, the Minkowski sum of the part with a ray; ``q`` blocks ``p`` along ``d`` when
that swept volume and ``q`` overlap by more than the penetration tolerance.

The test is exact for convex bodies (a body that is not convex is left to manifold3d's booleans,
:mod:`opportune.derive.solids`):
the swept volume of a convex body is a convex polyhedron (unbounded along ``-d``) whose faces are the
body's faces and the planes through its edges and ``d``, so by the separating axis theorem two bodies
overlap iff their projections overlap on every axis among the faces' normals of both, the cross
products of the body's edges with ``d``, and of the two bodies' edges.  The least of those overlaps is
the penetration depth (the shortest move that separates them), compared with the tolerance: touching
faces (overlap 0) never block, and a part slides along them.  Bounding boxes filter the pairs first,
with the same rule (a box's overlap on an axis is at least the depth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opportune.derive.geometry import Assembly, Body, GeometryError, cross

#: The six axis directions, ``--directions axes``: a name and a unit vector each.
AXES = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0),
        "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}
#: Cross products shorter than this (of unit vectors: nearly parallel edges) give no axis.
_PARALLEL = 1e-9


@dataclass(frozen=True)
class Blocking:
    """The blocking relation of an assembly.

    ``blockers[p][d]`` is the set of parts in ``p``'s way when it is inserted along direction ``d``
    (a name of ``directions``); ``checks`` counts the body-pair tests run (after the bounding boxes).
    """

    parts: tuple[str, ...]
    directions: dict[str, tuple[float, float, float]]
    blockers: dict[str, dict[str, frozenset[str]]]
    tolerance: float
    checks: int


def depth(a: Body, b: Body, sweep: np.ndarray | None = None) -> float:
    """How deep body ``a`` (swept along the ray ``sweep``, if given) and body ``b`` overlap: the least
    overlap of their projections over the separating axes; 0 or less when they do not overlap.

    Parameters
    ----------
    a, b : Body
        Convex bodies.
    sweep : numpy.ndarray, optional
        A unit vector: ``a`` is swept along ``{t·sweep : t ≥ 0}`` (``-d`` for insertion along ``d``).

    Returns
    -------
    float
        The penetration depth (metres), ``inf`` never (a swept body overlaps on a bounded range).

    Examples
    --------
    >>> from opportune.derive.geometry import Body
    >>> import numpy as np
    >>> cube = lambda x: Body(np.array([[x + i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float),
    ...                       np.eye(3), np.eye(3))
    >>> depth(cube(0), cube(1))                              # touching faces: no overlap
    0.0
    >>> depth(cube(0), cube(3), np.array([1.0, 0.0, 0.0]))   # swept along +x, into the other: 1 deep
    1.0
    """
    axes = [a.normals, b.normals, _crosses(a.edges, b.edges)]
    if sweep is not None:
        axes += [_crosses(a.edges, sweep[None, :]), _crosses(sweep[None, :], b.edges)]
    axes = np.vstack([x for x in axes if len(x)])
    pa, pb = a.vertices @ axes.T, b.vertices @ axes.T
    lo_a, hi_a = pa.min(axis=0), pa.max(axis=0)
    if sweep is not None:
        along = axes @ sweep
        hi_a = np.where(along > _PARALLEL, np.inf, hi_a)
        lo_a = np.where(along < -_PARALLEL, -np.inf, lo_a)
    overlap = np.minimum(hi_a, pb.max(axis=0)) - np.maximum(lo_a, pb.min(axis=0))
    return float(overlap.min())


def penetration(a: Body, b: Body, sweep: np.ndarray | None = None, reach: float = 0.0) -> float:
    """How deep body ``a`` (swept along ``sweep`` by up to ``reach``, if given) and body ``b`` overlap:
    the separating axes' depth for two convex bodies (:func:`depth`), else the overlap's mean thickness
    by manifold3d's booleans (:func:`opportune.derive.solids.thickness`).

    Parameters
    ----------
    a, b : Body
        Closed bodies.
    sweep : numpy.ndarray, optional
        A unit vector.
    reach : float
        How far ``a`` is swept (past the assembly); unused for convex pairs (the sweep is a ray).

    Returns
    -------
    float
        Metres; 0 or less when they do not overlap.

    Examples
    --------
    >>> from opportune.derive.geometry import Body
    >>> v = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    >>> penetration(Body(v, np.eye(3), np.eye(3)), Body(v + [1, 0, 0], np.eye(3), np.eye(3)))
    0.0
    """
    if a.convex and b.convex:
        return depth(a, b, sweep)
    from opportune.derive.solids import thickness

    return thickness(a, b, sweep, reach)


def _crosses(e: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The unit cross products of every vector of ``e`` with every one of ``f`` (parallel pairs left out)."""
    c = cross(e[:, None, :], f[None, :, :]).reshape(-1, 3)
    n = np.linalg.norm(c, axis=1)
    keep = n > _PARALLEL
    return c[keep] / n[keep, None]


def find_blocking(assembly: Assembly, directions: dict[str, tuple[float, float, float]] | None = None) -> Blocking:
    """For each part and each direction, the parts that block its insertion along that direction.

    Parameters
    ----------
    assembly : Assembly
        The parts in the assembled pose (:func:`opportune.derive.geometry.read_assembly`).
    directions : dict, optional
        Direction names and vectors (normalised here); default :data:`AXES`.

    Returns
    -------
    Blocking
        ``blockers[p][d]``, and the number of body-pair tests run.

    Raises
    ------
    GeometryError
        Two parts that overlap in the assembled pose by more than the tolerance (both named, with the depth).

    Examples
    --------
    >>> from opportune.derive.geometry import Assembly, Body, PartShape
    >>> import numpy as np
    >>> def cube(x):
    ...     v = np.array([[x + i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    ...     return PartShape(str(x), None, (Body(v, np.eye(3), np.eye(3)),), 12)
    >>> b = find_blocking(Assembly((cube(0), cube(1)), 1e-9, "m"))
    >>> sorted(d for d, q in b.blockers["0"].items() if q)    # 0 cannot come in moving -x: 1 is in its way
    ['-x']
    """
    directions = dict(AXES if directions is None else directions)
    unit = unit_vectors(directions)
    parts = assembly.parts
    tol = assembly.tolerance
    _check_apart(assembly, np.array([p.bounds for p in parts]))
    found: dict[str, dict[str, set[str]]] = {p.id: {d: set() for d in unit} for p in parts}
    checks = 0
    reach = 2 * assembly.size        # past the whole assembly: a part comes from far away
    for i, d, j, pairs in _candidates(assembly, unit):
        for a, b in pairs:
            checks += 1
            if penetration(a, b, -unit[d], reach) > tol:
                found[parts[i].id][d].add(parts[j].id)
                break
    blockers = {p: {d: frozenset(q) for d, q in dirs.items()} for p, dirs in found.items()}
    return Blocking(tuple(p.id for p in parts), directions, blockers, tol, checks)


def unit_vectors(directions: dict[str, tuple[float, float, float]]) -> dict[str, np.ndarray]:
    """The directions as unit vectors (numpy), by name.

    Parameters
    ----------
    directions : dict
        Names and vectors (not zero).

    Returns
    -------
    dict
        Names and unit vectors.

    Examples
    --------
    >>> unit_vectors({"d": (0, 3, 4)})["d"].tolist()
    [0.0, 0.6, 0.8]
    """
    return {d: np.asarray(v, float) / np.linalg.norm(v) for d, v in directions.items()}


def candidate_pairs(assembly: Assembly, unit: dict[str, np.ndarray]):
    """Every body pair the narrow phase must test: ``(i, direction, j, body of part i, body of part j)``
    for each part ``i`` swept along each direction and each part ``j`` whose box its swept box meets
    (the broad phase :func:`find_blocking` runs, flattened; the collision benchmark asks each method these).

    Parameters
    ----------
    assembly : Assembly
        The parts.
    unit : dict
        Direction names and unit vectors (:func:`unit_vectors`).

    Returns
    -------
    iterator of tuple
        ``(i, direction, j, a, b)``.

    Examples
    --------
    >>> from opportune.derive.geometry import Assembly, Body, PartShape
    >>> def cube(x):
    ...     v = np.array([[x + i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    ...     return PartShape(str(x), None, (Body(v, np.eye(3), np.eye(3)),), 12)
    >>> [(i, d, j) for i, d, j, _, _ in candidate_pairs(Assembly((cube(0), cube(1)), 1e-9, "m"), unit_vectors(AXES))]
    [(1, '+x', 0), (0, '-x', 1)]
    """
    for i, d, j, pairs in _candidates(assembly, unit):
        for a, b in pairs:
            yield i, d, j, a, b


def _candidates(assembly: Assembly, unit: dict[str, np.ndarray]):
    """The broad phase, in each direction's own frame (two axes across it and the direction itself, so
    that a tilted direction prunes as well as an axis): every part's box swept to infinity against every
    part's box at once (one n × n comparison), then, for each pair left, the bodies' boxes the same way.
    A box's overlap on an axis is at least the bodies' penetration depth, so no pair left out can block."""
    parts, tol = assembly.parts, assembly.tolerance
    for d, v in unit.items():
        frame = _frame(v)
        # each body's box too: a part's box overlapping another's says little when parts are long or bent
        body_boxes = [np.array([_box(b.vertices @ frame.T) for b in p.bodies]) for p in parts]
        boxes = np.array([[bb[:, 0].min(axis=0), bb[:, 1].max(axis=0)] for bb in body_boxes])
        swept = _swept_boxes(boxes)
        overlap = np.minimum(swept[:, None, 1], boxes[None, :, 1]) - np.maximum(swept[:, None, 0], boxes[None, :, 0])
        near = (overlap > tol).all(axis=2)
        np.fill_diagonal(near, False)
        for i, j in zip(*(k.tolist() for k in np.nonzero(near))):
            pairs = _box_pairs(_swept_boxes(body_boxes[i]), body_boxes[j], tol)
            if pairs:
                yield i, d, j, [(parts[i].bodies[a], parts[j].bodies[b]) for a, b in pairs]


def _frame(v: np.ndarray) -> np.ndarray:
    """Rows: two unit vectors across ``v`` and ``v`` itself (an orthonormal frame)."""
    other = np.eye(3)[int(np.argmin(np.abs(v)))]
    u = cross(v, other)
    u /= np.linalg.norm(u)
    return np.array([u, cross(v, u), v])


def _box(points: np.ndarray) -> np.ndarray:
    return np.array([points.min(axis=0), points.max(axis=0)])


def _swept_boxes(boxes: np.ndarray) -> np.ndarray:
    """Boxes (k × 2 × 3, in a direction's frame) swept from far away along the direction (the third
    axis): coming in along ``v``, a part passes everything behind where it ends."""
    out = boxes.copy()
    out[:, 0, 2] = -np.inf
    return out


def _box_pairs(a: np.ndarray, b: np.ndarray, tol: float) -> list[tuple[int, int]]:
    """The pairs of boxes of ``a`` and ``b`` that overlap by more than ``tol`` on every axis (a box's
    overlap on an axis is at least the bodies' penetration depth, so no other pair can block)."""
    overlap = np.minimum(a[:, None, 1], b[None, :, 1]) - np.maximum(a[:, None, 0], b[None, :, 0])
    return list(zip(*(k.tolist() for k in np.nonzero((overlap > tol).all(axis=2)))))


def _check_apart(assembly: Assembly, boxes: np.ndarray) -> None:
    """Refuse parts that overlap in the assembled pose by more than the tolerance."""
    parts, tol = assembly.parts, assembly.tolerance
    for i, p in enumerate(parts):
        overlap = np.minimum(boxes[i, 1], boxes[i + 1:, 1]) - np.maximum(boxes[i, 0], boxes[i + 1:, 0])
        for j in (i + 1 + np.nonzero((overlap > tol).all(axis=1))[0]).tolist():
            for a in p.bodies:
                for b in parts[j].bodies:
                    deep = penetration(a, b)
                    if deep > tol:
                        raise GeometryError(
                            f"parts {p.id!r} and {parts[j].id!r} overlap by {deep:.6g} m in the assembled pose "
                            f"(the tolerance is {tol:.6g} m): move them apart, or give a larger --tolerance")
