"""Bodies that are not convex, tested by manifold3d's exact booleans.

A body ``A`` swept from far away along a direction (moving along ``s``, the ray ``{t·s : 0 ≤ t ≤
reach}`` from its place backwards) covers ``A`` and, for each of its triangles ``T`` facing along the
sweep (outward normal · ``s`` > 0), the prism ``hull(T, T + reach·s)``: a point ``a + t·s`` outside
``A`` left ``A`` through such a triangle, at most ``t`` before.  That union, intersected with the
other body, is the overlap; manifold3d (chosen by ``benchmarks/bench_collision.py``: exact on every
measured assembly, and the fastest of the libraries) computes it in double precision.

The tolerance is compared with the overlap's mean thickness, twice its volume over its surface area:
for a thin sliver of depth ``δ`` that is ``δ`` (what the separating axes give for convex bodies), and a
third of the side for a cube-shaped overlap.
"""

from __future__ import annotations

import numpy as np

# not typing.TYPE_CHECKING: importing typing costs start-up time, and this module is imported lazily anyway
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.derive.geometry import Body


def solid(body: "Body", origin: np.ndarray | None = None):
    """The body as a manifold3d solid, in coordinates relative to ``origin`` (default the body's first vertex).

    Parameters
    ----------
    body : Body
        A closed body: its triangles where it has them, else (convex) the hull of its vertices.
    origin : numpy.ndarray, optional
        Subtracted from every coordinate first (the pair's frame: booleans round relative to size).

    Returns
    -------
    manifold3d.Manifold
        The solid.

    Raises
    ------
    ValueError
        A mesh manifold3d does not take as a solid (its status named).

    Examples
    --------
    >>> from opportune.derive.geometry import Body
    >>> cube = Body(np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float), np.eye(3), np.eye(3))
    >>> round(solid(cube).volume(), 9)
    1.0
    """
    import manifold3d

    origin = body.vertices[0] if origin is None else origin
    points = np.ascontiguousarray(body.vertices - origin, dtype=np.float64)
    if body.triangles is None:
        return manifold3d.Manifold.hull_points(points)
    out = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=points,
                                                tri_verts=np.ascontiguousarray(body.triangles, dtype=np.uint32)))
    status = out.status()
    if status != manifold3d.Error.NoError:
        raise ValueError(str(status).rsplit(".", 1)[-1])
    return out


def swept_solid(body: "Body", sweep: np.ndarray, reach: float, origin: np.ndarray):
    """The solid the body covers moving along ``sweep`` (a unit vector) by up to ``reach``: its hull with
    its moved copy when convex, else the body and one prism per triangle facing the sweep.

    Parameters
    ----------
    body : Body
        A closed body.
    sweep : numpy.ndarray
        A unit vector.
    reach : float
        How far it moves.
    origin : numpy.ndarray
        Subtracted from every coordinate first.

    Returns
    -------
    manifold3d.Manifold
        The swept solid.

    Examples
    --------
    >>> from opportune.derive.geometry import Body
    >>> v = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    >>> round(swept_solid(Body(v, np.eye(3), np.eye(3)), np.array([1.0, 0, 0]), 2.0, np.zeros(3)).volume(), 9)
    3.0
    """
    import manifold3d

    points = body.vertices - origin
    if body.convex:
        return manifold3d.Manifold.hull_points(np.ascontiguousarray(np.vstack([points, points + reach * sweep])))
    tri = points[body.triangles]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ahead = tri[normals @ sweep > 0]
    prisms = [manifold3d.Manifold.hull_points(np.ascontiguousarray(np.vstack([t, t + reach * sweep]))) for t in ahead]
    return manifold3d.Manifold.batch_boolean([solid(body, origin)] + prisms, manifold3d.OpType.Add)


def thickness(a: "Body", b: "Body", sweep: np.ndarray | None = None, reach: float = 0.0) -> float:
    """The mean thickness of the overlap of body ``a`` (swept along ``sweep`` by ``reach``, if given) and
    body ``b``: twice its volume over its surface area; 0 when they do not overlap.

    Parameters
    ----------
    a, b : Body
        Closed bodies (convex or not).
    sweep : numpy.ndarray, optional
        A unit vector: ``a`` moved along it by up to ``reach``.
    reach : float
        How far (past the assembly: everything beyond is empty).

    Returns
    -------
    float
        Metres.

    Examples
    --------
    >>> from opportune.derive.geometry import Body
    >>> def cube(x):
    ...     return Body(np.array([[x + i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float),
    ...                 np.eye(3), np.eye(3))
    >>> thickness(cube(0), cube(1)), round(thickness(cube(0), cube(3), np.array([1.0, 0, 0]), 10.0), 9)
    (0.0, 0.333333333)
    """
    origin = b.vertices.min(axis=0)
    moved = solid(a, origin) if sweep is None else swept_solid(a, sweep, reach, origin)
    both = moved ^ solid(b, origin)
    volume = both.volume()
    if volume <= 0:
        return 0.0
    return 2 * volume / both.surface_area()


#: How far (a share of the body's size) a corner must lie outside a face's plane for the face to be
#: reflex (a cut along it needed): well above the rounding of a cut's new corners, well below any feature.
REFLEX_SHARE = 1e-7


#: Steps (cuts, or a piece taken apart) allowed per piece wanted before a body is given up as needing too
#: many: a body of ``k`` convex blocks takes about ``2k`` steps.
CUTS_PER_PIECE = 4


def convex_pieces(body: "Body", most: int) -> list[np.ndarray] | None:
    """A body that is not convex cut into convex pieces along its own faces' planes (manifold3d's exact
    ``split_by_plane``): while a piece has a reflex edge (a corner of one of its two faces outside the other
    face's plane), it is cut along that face's plane, the largest such face first; a piece of several
    components is taken apart first.  A connected closed surface without a reflex edge is convex, and the
    test is local (each edge once): a cut costs O(n log n) in the piece's triangles.  The pieces' union is the body,
    exactly; a body that is a union of a few convex blocks (a U, an L, a cup) comes out as those blocks.

    Parameters
    ----------
    body : Body
        A closed body (a valid solid).
    most : int
        The most pieces wanted: a body that needs more (a curved surface that is not convex) gives None.

    Returns
    -------
    list of numpy.ndarray or None
        Each piece's corners, in metres, or None.

    Examples
    --------
    A U (a block with a slot cut across its top) is three blocks, its floor and its two posts:

    >>> import manifold3d
    >>> from opportune.derive.geometry import Body
    >>> u = manifold3d.Manifold.cube((3, 1, 2)) - manifold3d.Manifold.cube((1, 2, 1)).translate((1, -0.5, 1))
    >>> mesh = u.to_mesh64()
    >>> body = Body(np.asarray(mesh.vert_properties), np.eye(3), np.eye(3), np.asarray(mesh.tri_verts), False)
    >>> sorted(np.round(np.ptp(p, axis=0), 9).tolist() for p in convex_pieces(body, 64))    # their sides
    [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [3.0, 1.0, 1.0]]
    >>> convex_pieces(body, 2) is None
    True
    """
    origin = body.vertices.min(axis=0)
    size = max(float(np.ptp(body.vertices, axis=0).max()), 1e-300)
    eps = REFLEX_SHARE * size
    todo, done = [solid(body, origin)], []
    for _ in range(CUTS_PER_PIECE * most):      # bounded, whatever the cuts do
        if not todo:
            return done
        if len(done) + len(todo) > most:
            return None
        piece = todo.pop()
        parts = piece.decompose()
        if len(parts) > 1:
            todo += [part for part in parts if part.volume() > eps * size * size]
            continue
        mesh = piece.to_mesh64()
        points = np.asarray(mesh.vert_properties, dtype=float)[:, :3]
        plane = _reflex_plane(points, np.asarray(mesh.tri_verts, dtype=np.int64), eps)
        if plane is None:
            done.append(points + origin)
            continue
        # a cut along a face the piece only touches leaves a flat sliver on one side: nothing of the body
        todo += [half for half in piece.split_by_plane(*plane) if half.volume() > eps * size * size]
    return None


def _reflex_plane(points: np.ndarray, tri: np.ndarray, eps: float) -> tuple[tuple, float] | None:
    """The plane ``(normal, offset)`` of the largest face with a reflex edge (the neighbour across the edge has
    its third corner more than ``eps`` outside the face's plane) that has corners more than ``eps`` on both
    sides, or None: the piece has no reflex edge (or only flaps a cut left, within ``eps`` of flat)."""
    corners = points[tri]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = np.linalg.norm(normals, axis=1)
    units = normals / np.maximum(area, 1e-300)[:, None]
    n = len(points)
    # each triangle's edges a -> b with the corner opposite; the neighbour across is the edge b -> a
    a, b = tri.reshape(-1), tri[:, [1, 2, 0]].reshape(-1)
    opposite = tri[:, [2, 0, 1]].reshape(-1)
    face = np.repeat(np.arange(len(tri)), 3)
    key, twin_key = a * n + b, b * n + a
    order = np.argsort(key)
    at = np.clip(np.searchsorted(key[order], twin_key), 0, len(key) - 1)
    twin = order[at]
    paired = key[twin] == twin_key
    out = np.einsum("ij,ij->i", points[opposite[twin]] - points[a], units[face])
    reflex = paired & (out > eps) & (area[face] > 0)
    if not reflex.any():
        return None
    for k in sorted(set(face[reflex].tolist()), key=lambda k: -area[k]):
        side = points @ units[k] - units[k] @ points[tri[k, 0]]
        if side.max() > eps and side.min() < -eps:     # a cut that splits (not a flap left by an earlier cut)
            return tuple(float(c) for c in units[k]), float(units[k] @ points[tri[k, 0]])
    return None
