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

from opportune.derive.geometry import Assembly, Body

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
    >>> from opportune.derive.geometry import Assembly, Body, PartShape
    >>> def cube(x, z=0):
    ...     v = np.array([[x + i, j, z + k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    ...     return PartShape(f"c{x}{z}", None, (Body(v, np.eye(3), np.eye(3)),), 12)
    >>> [(c.a, c.b, c.normal, c.area) for c in find_contacts(Assembly((cube(0), cube(0, 1), cube(2)), 1e-9, "m"))]
    [('c00', 'c01', (0.0, 0.0, 1.0), 1.0)]
    """
    parts, tol = assembly.parts, assembly.tolerance
    boxes = np.array([p.bounds for p in parts])
    out = []
    for i, p in enumerate(parts):
        gap = np.maximum(boxes[i, 0], boxes[i + 1:, 0]) - np.minimum(boxes[i, 1], boxes[i + 1:, 1])
        for j in (i + 1 + np.nonzero((gap <= tol).all(axis=1))[0]).tolist():
            for a in p.bodies:
                for b in parts[j].bodies:
                    for normal, area in body_contacts(a, b, tol):
                        out.append(Contact(p.id, parts[j].id, tuple(float(x) for x in normal), area))
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
    out = []
    for n in np.vstack([a.normals, -a.normals, b.normals, -b.normals]):
        top, bottom = a.vertices @ n, b.vertices @ n
        if abs(bottom.min() - top.max()) > tol or any(np.allclose(n, m) for m, _ in out):
            continue
        area, side = _patch_area(a.vertices[top >= top.max() - tol], b.vertices[bottom <= bottom.min() + tol], n)
        if area > tol * side:
            out.append((n, area))
    return out


def _patch_area(pa: np.ndarray, pb: np.ndarray, n: np.ndarray) -> tuple[float, float]:
    """The area of the overlap of two faces' hulls in the plane across ``n``, and its longest side
    (coordinates scaled to the faces' size first: the 2-D booleans round to a fixed precision)."""
    import manifold3d

    if len(pa) < 3 or len(pb) < 3:
        return 0.0, 0.0
    other = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, other)
    u /= np.linalg.norm(u)
    basis = np.array([u, np.cross(n, u)]).T
    qa, qb = pa @ basis, pb @ basis
    origin = qa.min(axis=0)
    scale = max(float(np.ptp(np.vstack([qa, qb]), axis=0).max()), 1e-300)
    both = (manifold3d.CrossSection.hull_points((qa - origin) / scale)
            ^ manifold3d.CrossSection.hull_points((qb - origin) / scale))
    if both.is_empty():
        return 0.0, 0.0
    (x0, y0, x1, y1) = both.bounds()
    return both.area() * scale * scale, max(x1 - x0, y1 - y0) * scale
