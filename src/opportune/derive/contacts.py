"""Where parts touch in the assembled pose: contact patches, their normals and areas.

Two convex bodies touch along a plane when their projections on one of their faces' normals meet
within the penetration tolerance; the patch is the overlap, in that plane, of the two bodies' faces
lying on it (each body's vertices within the tolerance of the plane, hulled), measured by
manifold3d's 2-D booleans.  A patch counts as a contact when it is wider than the tolerance
(``area > tolerance × its longest side``): bodies meeting along an edge or at a corner do not touch.

The contacts give ``--gravity`` its supports (a part rests on a part it touches from above: the
contact's normal, from the lower part to the upper, points up by more than :data:`UPWARD`), give
``--connected`` what each part touches, and give the default directions the contacts' normals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opportune.derive.geometry import Assembly, Body, cross

#: A contact supports the part above when its normal (lower part to upper) has at least this component
#: up (against gravity): a face tilted up by more than about 0.06° holds a part (friction aside).
UPWARD = 1e-3


@dataclass(frozen=True)
class Contact:
    """Two parts touching: ``normal`` points from part ``a`` into part ``b``; ``area`` in square metres."""

    a: str
    b: str
    normal: tuple[float, float, float]
    area: float


def find_contacts(assembly: Assembly) -> list[Contact]:
    """Every contact patch between two parts' convex bodies, in the parts' order.

    Parameters
    ----------
    assembly : Assembly
        The parts in the assembled pose.

    Returns
    -------
    list of Contact
        One per touching body pair and plane (a part pair may touch along several planes).

    Examples
    --------
    >>> from opportune.derive.geometry import Assembly, Body, cross, PartShape
    >>> def cube(x, z=0):
    ...     v = np.array([[x + i, j, z + k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    ...     return PartShape(f"c{x}{z}", None, (Body(v, np.eye(3), np.eye(3)),), 12)
    >>> [(c.a, c.b, c.normal, c.area) for c in find_contacts(Assembly((cube(0), cube(0, 1), cube(2)), 1e-9, "m"))]
    [('c00', 'c01', (0.0, 0.0, 1.0), 1.0)]
    """
    parts, tol = assembly.parts, assembly.tolerance
    boxes = np.array([p.bounds for p in parts])
    body_boxes = [np.array([[b.vertices.min(axis=0), b.vertices.max(axis=0)] for b in p.bodies]) for p in parts]
    out = []
    for i, p in enumerate(parts):
        gap = np.maximum(boxes[i, 0], boxes[i + 1:, 0]) - np.minimum(boxes[i, 1], boxes[i + 1:, 1])
        for j in (i + 1 + np.nonzero((gap <= tol).all(axis=1))[0]).tolist():
            # only bodies whose boxes meet can touch
            near = (np.maximum(body_boxes[i][:, None, 0], body_boxes[j][None, :, 0])
                    - np.minimum(body_boxes[i][:, None, 1], body_boxes[j][None, :, 1]) <= tol).all(axis=2)
            for a, b in zip(*np.nonzero(near)):
                for normal, area in body_contacts(p.bodies[a], parts[j].bodies[b], tol):
                    out.append(Contact(p.id, parts[j].id, tuple(float(x) + 0.0 for x in normal), area))
    return out


def body_contacts(a: Body, b: Body, tol: float) -> list[tuple[np.ndarray, float]]:
    """The planes along which convex bodies ``a`` and ``b`` touch: ``(normal from a to b, patch area)``.

    Parameters
    ----------
    a, b : Body
        Convex bodies that do not overlap by more than ``tol``.
    tol : float
        The penetration tolerance (metres).

    Returns
    -------
    list of tuple
        Each touching plane once, with its patch's area (over ``tol`` × the patch's longest side).

    Examples
    --------
    >>> cube = lambda x: Body(np.array([[x + i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float),
    ...                       np.eye(3), np.eye(3))
    >>> [(n.tolist(), area) for n, area in body_contacts(cube(0), cube(1), 1e-9)]
    [([1.0, 0.0, 0.0], 1.0)]
    """
    if not (a.convex and b.convex):
        return _mesh_contacts(a, b, tol)
    normals = np.vstack([a.normals, -a.normals, b.normals, -b.normals])
    top, bottom = a.vertices @ normals.T, b.vertices @ normals.T
    # a plane the two bodies meet in: a's farthest along the normal, b's nearest, within the tolerance
    touching = np.abs(bottom.min(axis=0) - top.max(axis=0)) <= tol
    out = []
    for k in np.nonzero(touching)[0]:
        n = normals[k]
        if any(np.abs(n - m).max() < 1e-9 for m, _ in out):
            continue
        area, side = _patch_area(a.vertices[top[:, k] >= top[:, k].max() - tol],
                                 b.vertices[bottom[:, k] <= bottom[:, k].min() + tol], n)
        if area > tol * side:
            out.append((n, area))
    return out


def _mesh_contacts(a: Body, b: Body, tol: float) -> list[tuple[np.ndarray, float]]:
    """Contacts of bodies that are not both convex, triangle by triangle: triangles of ``a`` and ``b`` facing
    each other (opposite normals) in one plane (within ``tol``), overlapped per plane by manifold3d's 2-D
    booleans.  Only triangles near the other body's box are compared, in bounded blocks."""
    ta, tb = _near_triangles(a, b, tol), _near_triangles(b, a, tol)
    if not len(ta) or not len(tb):
        return []
    na, nb = _unit_normals(ta), _unit_normals(tb)
    groups: dict[tuple, tuple[np.ndarray, set, set]] = {}
    step = max(1, 2_000_000 // len(tb))      # rows per block: a block compares at most 2,000,000 pairs
    for lo in range(0, len(ta), step):
        facing = na[lo:lo + step] @ nb.T < -1 + 1e-9
        gap = np.abs(np.einsum("ij,ij->i", na[lo:lo + step], ta[lo:lo + step, 0])[:, None] - na[lo:lo + step] @ tb[:, 0].T)
        for i, j in zip(*np.nonzero(facing & (gap <= tol))):
            n = na[lo + i]
            key = tuple(np.round(n, 6)) + (round(float(n @ ta[lo + i, 0]) / max(tol, 1e-300)),)
            groups.setdefault(key, (n, set(), set()))
            groups[key][1].add(lo + int(i))
            groups[key][2].add(int(j))
    out = []
    for n, ia, ib in groups.values():
        area, side = _patch_area(ta[sorted(ia)], tb[sorted(ib)], n, union=True)
        if area > tol * side:
            out.append((n, area))
    return out


def _near_triangles(a: Body, b: Body, tol: float) -> np.ndarray:
    """``a``'s triangles (k × 3 × 3) whose boxes come within ``tol`` of ``b``'s box."""
    tri = a.vertices[a.triangles]
    lo, hi = b.vertices.min(axis=0) - tol, b.vertices.max(axis=0) + tol
    keep = (tri.max(axis=1) >= lo).all(axis=1) & (tri.min(axis=1) <= hi).all(axis=1)
    return tri[keep]


def _unit_normals(tri: np.ndarray) -> np.ndarray:
    n = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _patch_area(pa: np.ndarray, pb: np.ndarray, n: np.ndarray, union: bool = False) -> tuple[float, float]:
    """The area of the overlap of two faces in the plane across ``n`` (each the hull of its points, or with
    ``union`` the union of its triangles, k × 3 × 3), and its longest side (coordinates scaled to the faces'
    size first: the 2-D booleans round to a fixed precision)."""
    import manifold3d

    if not union and (len(pa) < 3 or len(pb) < 3):
        return 0.0, 0.0
    other = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = cross(n, other)
    u /= np.linalg.norm(u)
    basis = np.array([u, cross(n, u)]).T
    qa, qb = pa @ basis, pb @ basis
    flat = np.vstack([qa.reshape(-1, 2), qb.reshape(-1, 2)])
    origin = flat.min(axis=0)
    scale = max(float(np.ptp(flat, axis=0).max()), 1e-300)

    def face(q):
        q = (q - origin) / scale
        if not union:
            return manifold3d.CrossSection.hull_points(q)
        return manifold3d.CrossSection.batch_boolean([manifold3d.CrossSection.hull_points(t) for t in q],
                                                     manifold3d.OpType.Add)

    both = face(qa) ^ face(qb)
    if both.is_empty():
        return 0.0, 0.0
    (x0, y0, x1, y1) = both.bounds()
    return both.area() * scale * scale, max(x1 - x0, y1 - y0) * scale
