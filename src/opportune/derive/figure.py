"""An exploded view of a derived plan: each part moved out along its insertion direction, coloured by stage.

One strategy of the plan (the first by default; of a plan written as ways, one feasible sequence read as
a strategy: :func:`~opportune.derive.waysfacts.sequence_strategy`) gives each part its insertion
direction ``d`` and an order.  A part's **stage** is its earliest position in a sequence the strategy admits (one more than
the parts that must go in before it); its **level** is the length of the longest chain of
constraints that ends at it.  The part is drawn moved back along ``-d`` (where it comes from) by
``(level + 1) × gap`` plus its own length along ``d`` (a long shaft clears the short parts on its
line), but for the largest part (the base, most often), which stays: the parts that
close the product fly furthest.  A part is drawn coming from above (``-z``) wherever the strategy's
order allows that (:func:`shown_directions`).  A dashed line joins each moved part to its place; colours (a colour bar) give the stage.
All the faces are depth-sorted together (one collection), drawn with matplotlib's 3-D axes, in
millimetres, at a size that reads in print (7 × 5.5 inches; PNG at 200 dpi, or SVG/PDF).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from opportune.derive.plan import way_direction

#: The figure's size in inches: a page's width.
FIGSIZE = (7.0, 5.5)
#: The explosion's step, as a share of the assembly's size (its bounding box's diagonal).
GAP_SHARE = 0.45
#: The formats written, by suffix.
FORMATS = (".png", ".svg", ".pdf")
#: Points closer than this share of a body's size to a face's plane lie on it.
_ON_FACE = 1e-7


def faces(vertices: np.ndarray, normals: np.ndarray) -> list[np.ndarray]:
    """The faces of a convex body, each a polygon of its corners in order: for each normal's line, the
    vertices at either extreme, when three or more (a face, not an edge or a corner).

    Parameters
    ----------
    vertices : numpy.ndarray
        The body's corners (k × 3).
    normals : numpy.ndarray
        Its faces' normals, each line once, either sign (as :class:`~opportune.derive.geometry.Body` has them).

    Returns
    -------
    list of numpy.ndarray
        Polygons (m × 3), corners around the face.

    Examples
    --------
    >>> cube = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    >>> len(faces(cube, np.eye(3)))
    6
    """
    size = max(float(np.ptp(vertices, axis=0).max()), 1e-300)
    out = []
    for n in normals:
        h = vertices @ n
        for extreme in (h.max(), h.min()):
            on = vertices[np.abs(h - extreme) <= _ON_FACE * size]
            if len(on) < 3:
                continue
            centre = on.mean(axis=0)
            u = on[0] - centre
            u /= np.linalg.norm(u) or 1.0
            v = np.cross(n, u)
            angles = np.arctan2((on - centre) @ v, (on - centre) @ u)
            out.append(on[np.argsort(angles)])
    return out


def levels(parts: tuple[str, ...], pairs) -> tuple[dict[str, int], dict[str, int]]:
    """Each part's level (the longest chain of constraints ending at it) and stage (its earliest position:
    one more than the parts that must precede it).

    Parameters
    ----------
    parts : tuple of str
        The part ids.
    pairs : iterable of (str, str)
        The strategy's ``(before, after)`` constraints (acyclic).

    Returns
    -------
    tuple of dict
        ``(level, stage)`` by part.

    Examples
    --------
    >>> levels(("a", "b", "c"), [("a", "b"), ("b", "c")])
    ({'a': 0, 'b': 1, 'c': 2}, {'a': 1, 'b': 2, 'c': 3})
    """
    before: dict[str, set[str]] = {p: set() for p in parts}
    for a, b in pairs:
        before[b].add(a)
    level: dict[str, int] = {}
    ancestors: dict[str, set[str]] = {}

    def visit(p: str) -> None:
        # parts in order: a part's predecessors are visited first (an explicit stack: no recursion limit)
        stack = [p]
        while stack:
            q = stack[-1]
            todo = [r for r in before[q] if r not in level]
            if todo:
                stack.extend(todo)
                continue
            stack.pop()
            if q not in level:
                level[q] = max((level[r] + 1 for r in before[q]), default=0)
                ancestors[q] = set().union(*(ancestors[r] | {r} for r in before[q])) if before[q] else set()

    for p in parts:
        visit(p)
    return {p: level[p] for p in parts}, {p: len(ancestors[p]) + 1 for p in parts}


def exploded(derivation, path: str | Path, *, strategy: int = 1, gap: float | None = None,
             title: str | None = None) -> Path:
    """Draw the exploded view of a derived plan's strategy into ``path`` (``.png``, ``.svg`` or ``.pdf``).

    Parameters
    ----------
    derivation : Derivation
        What :func:`opportune.derive.derive` returned (it carries the assembly's geometry).
    path : str or Path
        The file to write; its suffix chooses the format.
    strategy : int
        Which strategy gives the directions and the order, counting from 1.
    gap : float, optional
        The explosion's step in metres (default :data:`GAP_SHARE` of the assembly's size).
    title : str, optional
        The figure's title (default: the plan's name and the strategy).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        A suffix not in :data:`FORMATS`, a strategy the plan does not have (a plan written as ways has one
        to draw), or a derivation without geometry.

    Examples
    --------
    >>> import tempfile
    >>> from opportune.derive import derive
    >>> out = exploded(derive("geometry:gearbox"), Path(tempfile.mkdtemp()) / "gearbox.svg")
    >>> out.stat().st_size > 10_000
    True
    """
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise ValueError(f"{path.name}: write the figure as {', '.join(FORMATS)} (the suffix chooses)")
    if derivation.assembly is None:
        raise ValueError("the derivation carries no geometry: derive it from the meshes")
    if derivation.plan.is_ways:
        if strategy != 1:
            raise ValueError(f"strategy {strategy}: the plan is written as each part's ways in, and the figure "
                             "draws one feasible sequence of it (give 1)")
        from opportune.derive.waysfacts import sequence_strategy

        chosen, what = sequence_strategy(derivation), "one feasible sequence"
    elif not 1 <= strategy <= len(derivation.strategies):
        raise ValueError(f"strategy {strategy}: the plan has {len(derivation.strategies)} (give 1 to "
                         f"{len(derivation.strategies)})")
    else:
        chosen, what = derivation.strategies[strategy - 1], f"strategy s{strategy}"
    assembly = derivation.assembly
    level, stage = levels(derivation.blocking.parts, chosen.pairs)
    step = GAP_SHARE * assembly.size if gap is None else float(gap)
    unit = {d: np.asarray(v, float) / np.linalg.norm(v) for d, v in derivation.blocking.directions.items()}
    directions = shown_directions(derivation.blocking, chosen)
    # the largest part stays (the product's base, most often), every other moves one step more than its level,
    # and its own length along the way it moves (a long shaft drawn clear of the short parts on its line)
    anchor = max(assembly.parts, key=lambda p: float(np.prod(np.ptp(p.bounds, axis=0))) if len(p.bodies) else 0.0).id
    moves = {p.id: np.zeros(3) if p.id == anchor else
             -unit[directions[p.id]] * (step * (level[p.id] + 1) + _length(p, unit[directions[p.id]]))
             for p in assembly.parts}
    fig = _draw(assembly, moves, stage, title or f"{derivation.plan.name}: each part moved out along its insertion "
                                                  f"direction ({what})")
    fig.savefig(path, dpi=200, bbox_inches="tight")
    return path


def _length(part, unit: np.ndarray) -> float:
    """The part's extent along a unit vector (its bodies' corners projected)."""
    if not len(part.bodies):
        return 0.0
    along = np.concatenate([b.vertices @ unit for b in part.bodies])
    return float(along.max() - along.min())


def shown_directions(block, strategy) -> dict[str, str]:
    """The direction each part is drawn coming from: straight down (``-z``) where the strategy's order allows
    it (every part in its way there comes after it), else the strategy's own direction.

    Parameters
    ----------
    block : Blocking
        The blocking relation.
    strategy : DerivedStrategy
        The strategy drawn.

    Returns
    -------
    dict
        Part id → direction name.

    Examples
    --------
    >>> from opportune.derive.blocking import Blocking
    >>> from opportune.derive.plan import DerivedStrategy
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0), "-z": (0, 0, -1)},
    ...              {"a": {"+x": frozenset("b"), "-z": frozenset("b")}, "b": {"+x": frozenset(), "-z": frozenset("a")}},
    ...              0, 0)
    >>> shown_directions(b, DerivedStrategy({"a": "+x", "b": "+x"}, (("a", "b"),)))
    {'a': '-z', 'b': '+x'}
    """
    after: dict[str, set[str]] = {p: set() for p in block.parts}
    for p in reversed(_topological(block.parts, strategy.pairs)):
        after[p] = set().union(*({q} | after[q] for a, q in strategy.pairs if a == p)) if strategy.pairs else set()
    out = {}
    for p in block.parts:
        down = "-z" if "-z" in block.blockers[p] else None
        out[p] = down if down and block.blockers[p][down] <= after[p] else way_direction(block, p, strategy.directions[p])
    return out


def _topological(parts, pairs) -> list[str]:
    """The parts in an order the pairs allow (by level)."""
    level, _ = levels(parts, pairs)
    return sorted(parts, key=lambda p: level[p])


def _draw(assembly, moves: dict[str, np.ndarray], stage: dict[str, int], title: str):
    """The figure: every face of every moved part in one depth-sorted collection, paths, labels, a colour bar."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import BoundaryNorm
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = Figure(figsize=FIGSIZE)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    top = max(stage.values())
    cmap = _colours()
    norm = BoundaryNorm(np.arange(0.5, top + 1.5), cmap.N)
    polys, colours, points, paths, labels = [], [], [], [], []
    for part in assembly.parts:
        shift = moves[part.id] * 1000
        colour = cmap(norm(stage[part.id]))
        for body in part.bodies:
            for face in faces(body.vertices * 1000, body.normals):
                polys.append(face + shift)
                colours.append(colour)
        centre = part.bounds.mean(axis=0) * 1000
        points += [centre, centre + shift]
        if np.linalg.norm(shift) > 0:
            paths.append((centre, centre + shift))
        # a part id is the user's text: a "$" would start matplotlib's mathtext
        labels.append((centre + shift + np.array([0, 0, 0.04 * assembly.size * 1000]), part.id.replace("$", r"\$")))
    every = np.vstack([np.vstack(polys), np.array(points)])
    lo, hi = every.min(axis=0), every.max(axis=0)
    # the limits first and no autoscaling: mplot3d's autoscale of lines and text can overflow to infinite limits
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_autoscale_on(False)
    ax.set_box_aspect(np.maximum(hi - lo, 1e-9 * (hi - lo).max()))
    ax.add_collection3d(Poly3DCollection(polys, facecolors=colours, edgecolors="0.15", linewidths=0.3, alpha=0.95),
                        autolim=False)
    for a, b in paths:
        ax.plot(*zip(a, b), color="0.45", linestyle=(0, (3, 2)), linewidth=0.7)
    for at, text in labels:
        ax.text(*at, text, fontsize=7, ha="center", va="bottom", zorder=10,
                bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none", "alpha": 0.75})
    ax.view_init(elev=24, azim=-58)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):   # white panes, no grid: the parts are the figure
        axis.pane.fill = False
        axis.pane.set_edgecolor("0.8")
    ax.grid(False)
    from matplotlib.ticker import MaxNLocator

    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(4))
    for axis, name in zip((ax.set_xlabel, ax.set_ylabel, ax.set_zlabel), "xyz"):
        axis(f"{name} (mm)", fontsize=8, labelpad=1)
    ax.tick_params(labelsize=6, pad=0)
    fig.suptitle(title.replace("$", r"\$"), fontsize=9)
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, pad=0.08,
                       ticks=range(1, top + 1) if top <= 20 else None)
    bar.set_label("stage: earliest position in a sequence", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    return fig


def _colours():
    """The stages' colour map: viridis from a lighter violet (the first stage is not near black), readable in grey
    and by the colour-blind."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    return ListedColormap(colormaps["viridis"](np.linspace(0.2, 1.0, 256)))
