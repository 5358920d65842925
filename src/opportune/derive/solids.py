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
