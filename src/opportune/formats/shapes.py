"""A part's real shape in a plan: ``geometry: {convex: [[[x, y, z], ...], ...]}``, a union of convex bodies.

``opportune derive`` writes it (each body's corners in the assembled pose, metres), and the physical
bin (``simulate --bin physics``) heaps those shapes, each body the convex hull of its corners.  A
shape is bounded before anything is built from it, by the schema and by :func:`shape_problems`:

* at most :data:`~opportune.limits.MAX_SHAPE_BODIES` bodies a part, :data:`~opportune.limits.MAX_BODY_POINTS`
  corners a body (at least 4), every coordinate within ±:data:`COORDINATE` m (the schema);
* at most :data:`~opportune.limits.MAX_SHAPE_POINTS` corners in all the plan's shapes (checked with the
  sizes, before the schema: the validator's time grows with them);
* each part's extent from ``MIN_DIMENSION`` to ``MAX_DIMENSION`` along its largest side and at most
  ``MAX_DIMENSION`` along each, as the box and cylinder shapes; each body at least :data:`THICKNESS`
  thick across its flattest direction (a flat body has no volume to collide with).

>>> shape_problems([{"id": "a", "geometry": {"convex": [[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]]}}])
[(0, "part 'a': its shape is 1 m long; a part's shape is at most 0.5 m along each side")]
"""

from __future__ import annotations

from opportune.limits import MAX_SHAPE_POINTS

#: Every coordinate of a shape's corners within ± this many metres (the schema's bound).
COORDINATE = 10.0
#: Metres a body must be thick, at least, across its flattest direction (its points' spread along their
#: least principal axis): a tenth of a millimetre.
THICKNESS = 1e-4
HINT = ("write `geometry: {convex: [[[x, y, z], ...], ...]}`: a list of bodies, each the corners of a convex "
        "body (4 or more) in metres, or a box or a cylinder")


def count_points(parts) -> int:
    """The corners in all the shapes of a plan's ``parts`` list (anything malformed counts 0).

    >>> count_points([{"id": "a", "geometry": {"convex": [[[0, 0, 0]] * 5]}}, "b"])
    5
    """
    total = 0
    if not isinstance(parts, list):
        return 0
    for item in parts:
        geometry = item.get("geometry") if isinstance(item, dict) else None
        bodies = geometry.get("convex") if isinstance(geometry, dict) else None
        if isinstance(bodies, list):
            total += sum(len(b) for b in bodies if isinstance(b, list))
    return total


def too_many_points(parts) -> str | None:
    """The message if a plan's shapes hold more than :data:`~opportune.limits.MAX_SHAPE_POINTS` corners."""
    n = count_points(parts)
    if n > MAX_SHAPE_POINTS:
        return (f"the parts' shapes have {n:,} corners in all; a plan holds at most {MAX_SHAPE_POINTS:,}: "
                "simplify the shapes (fewer bodies, fewer corners) or leave some out")
    return None


def shape_problems(parts) -> list[tuple[int, str]]:
    """The problems of the (schema-valid) convex shapes of a plan's ``parts``: ``(index, message)`` each.

    Parameters
    ----------
    parts : list
        The plan's ``parts`` entries, past the schema.

    Returns
    -------
    list of (int, str)
        The part's index in the list and what is wrong, naming the part.

    Examples
    --------
    >>> flat = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]]
    >>> shape_problems([{"id": "plate", "geometry": {"convex": [flat]}}])[0][1].split(" (")[0]
    "part 'plate': body 1 is flat"
    """
    from opportune.planning.plan import MAX_DIMENSION, MIN_DIMENSION

    out = []
    for i, item in enumerate(parts):
        geometry = item.get("geometry") if isinstance(item, dict) else None
        if not (isinstance(geometry, dict) and "convex" in geometry):
            continue
        import numpy as np

        bodies = [np.asarray(b, float) for b in geometry["convex"]]
        every = np.vstack(bodies)
        extent = every.max(axis=0) - every.min(axis=0)
        who = f"part {item['id']!r}"
        if extent.max() > MAX_DIMENSION:
            out.append((i, f"{who}: its shape is {extent.max():.3g} m long; a part's shape is at most "
                           f"{MAX_DIMENSION:g} m along each side"))
        elif extent.max() < MIN_DIMENSION:
            out.append((i, f"{who}: its shape is {extent.max():.3g} m long; a part's shape is at least "
                           f"{MIN_DIMENSION:g} m along its longest side"))
        for k, b in enumerate(bodies, 1):
            thick = thickness(b)
            if thick < THICKNESS:
                out.append((i, f"{who}: body {k} is flat ({thick:.3g} m thick across its flattest direction); "
                               f"each body is at least {THICKNESS:g} m thick"))
                break
    return out


def thickness(points) -> float:
    """The spread of ``points`` (k × 3) along their least principal axis: how thick a body is, about.

    >>> thickness([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0.5]]) > 0.3
    True
    """
    import numpy as np

    points = np.asarray(points, float)
    centred = points - points.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][-1]
    h = centred @ axis
    return float(h.max() - h.min())
