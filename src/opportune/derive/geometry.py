"""An assembly in its assembled pose, read from a folder of meshes: one file a part (or from a scene:
:mod:`opportune.derive.scene`).

Each ``.obj``, ``.stl`` or ``.ply`` file of the folder is one part, its id the file's stem; other
files are left alone.  Coordinates are metres, or millimetres with ``units="mm"`` (scaled to metres
as read).  Meshes are read by trimesh, then checked before any blocking test: every coordinate
finite, at least one triangle, no degenerate triangle, every body (connected piece) closed, oriented
and not crossing itself (:func:`_check_not_crossing`).  A body
that is convex is tested by opportune's separating axes (:mod:`opportune.derive.blocking`, exact on
convex polyhedra); one that is not, by manifold3d's exact booleans (it must then be a valid manifold:
closed, oriented, not crossing itself).  Every refusal is a :class:`GeometryError` naming the part and
saying what to do.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from opportune.limits import MAX_COORDINATE, MAX_ID, MAX_MESH_BYTES, MAX_MESH_PARTS, MAX_TRIANGLES

#: The mesh formats read, by file suffix.
SUFFIXES = (".obj", ".stl", ".ply")
#: The scene files read as a whole assembly (:mod:`opportune.derive.scene`): glTF, GLB, MuJoCo's MJCF, STEP.
SCENE_SUFFIXES = (".glb", ".gltf", ".xml", ".mjcf", ".step", ".stp")
#: Units the files may be in, and their length in metres.
UNITS = {"m": 1.0, "mm": 0.001}
#: The default penetration tolerance, as a share of the assembly's size (its bounding box's diagonal):
#: well above float rounding of coordinates, well below any real clearance.
TOLERANCE_SHARE = 1e-6


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products over the last axis, broadcast (``numpy.cross`` without its per-call overhead, which
    dominated the narrow phase and the contacts).

    Parameters
    ----------
    a, b : numpy.ndarray
        Arrays whose last axis has length 3.

    Returns
    -------
    numpy.ndarray
        ``a × b``.

    Examples
    --------
    >>> cross(np.array([1.0, 0, 0]), np.array([0.0, 1, 0])).tolist()
    [0.0, 0.0, 1.0]
    """
    return (a[..., [1, 2, 0]] * b[..., [2, 0, 1]]) - (a[..., [2, 0, 1]] * b[..., [1, 2, 0]])


class GeometryError(ValueError):
    """An assembly that cannot be read or used: the message names the part and says what to do.

    Examples
    --------
    >>> read_assembly("no-such-folder", units="inch")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: units 'inch': give one of m, mm
    """


@dataclass(frozen=True)
class Body:
    """One closed piece of a part: its vertices, its faces' outward unit normals and its edges' unit
    directions (each direction once), all in metres; its triangles (indices into ``vertices``, outward)
    where read from a file; ``convex`` False for a piece that is not (tested by manifold3d's booleans
    instead of the separating axes)."""

    vertices: np.ndarray
    normals: np.ndarray
    edges: np.ndarray
    triangles: np.ndarray | None = None
    convex: bool = True


@dataclass(frozen=True)
class PartShape:
    """A part of the assembly: its id, its file and its convex bodies in the assembled pose."""

    id: str
    file: Path
    bodies: tuple[Body, ...]
    triangles: int

    @property
    def bounds(self) -> np.ndarray:
        """The part's axis-aligned bounding box, ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``."""
        points = np.vstack([b.vertices for b in self.bodies])
        return np.array([points.min(axis=0), points.max(axis=0)])


@dataclass(frozen=True)
class Assembly:
    """The parts in their assembled pose (sorted by id) and the penetration tolerance in metres.

    :func:`read_assembly` (a folder of meshes), :func:`~opportune.derive.scene.read_scene_assembly` (glTF,
    GLB, STEP) and :func:`~opportune.derive.mjcf.read_mjcf_assembly` (MJCF) make it;
    :func:`~opportune.derive.derive` takes one in place of a path.

    Parameters
    ----------
    parts : tuple of PartShape
        Each part's id, file and closed bodies, in metres.
    tolerance : float
        How far two parts may overlap and still count as touching, in metres.
    units : str
        The files' unit of length (a key of :data:`UNITS`).

    Examples
    --------
    >>> from opportune.datasets import geometry_path
    >>> a = read_assembly(geometry_path("gearbox"))
    >>> len(a.parts), a.parts[0].id, round(a.size, 3), a.units
    (14, 'bearing_a1', 0.141, 'm')
    """

    parts: tuple[PartShape, ...]
    tolerance: float
    units: str

    @property
    def size(self) -> float:
        """The diagonal of the assembly's bounding box, in metres."""
        boxes = np.vstack([p.bounds for p in self.parts])
        return float(np.linalg.norm(boxes.max(axis=0) - boxes.min(axis=0)))


def read_assembly(path: str | Path, *, units: str = "m", tolerance: float | None = None) -> Assembly:
    """Read a folder of meshes (one file a part) in the assembled pose.

    Parameters
    ----------
    path : str or Path
        The folder.  Its ``.obj``, ``.stl`` and ``.ply`` files are the parts (the id is the stem).
    units : str
        ``"m"`` (default) or ``"mm"``: the files' unit of length.
    tolerance : float, optional
        The penetration tolerance in the files' units: parts may overlap by this much (touching faces
        are not collisions).  Default: a millionth of the assembly's size (:data:`TOLERANCE_SHARE`).

    Returns
    -------
    Assembly
        The parts, each a tuple of closed bodies, in metres.

    Raises
    ------
    GeometryError
        A folder that is missing or holds no mesh, over :data:`~opportune.limits.MAX_MESH_PARTS` parts,
        two files of one stem, a file over :data:`~opportune.limits.MAX_MESH_BYTES` bytes or
        :data:`~opportune.limits.MAX_TRIANGLES` triangles, or a mesh that is unreadable, empty, not
        finite, degenerate, open, or crossing itself: the message names the file and the part.

    Examples
    --------
    >>> read_assembly("no-such-folder")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: no-such-folder: not a folder; give a folder of meshes, one file a part (.obj, .stl, .ply)
    """
    check_units(units, tolerance)
    parts = tuple(_read_part(stem, file, UNITS[units]) for stem, file in _mesh_files(Path(path)))
    return assembly_of(parts, units, tolerance)


def check_units(units: str, tolerance: float | None) -> None:
    """Refuse units not known and a tolerance that is not a finite length of 0 or more.

    Parameters
    ----------
    units : str
        A key of :data:`UNITS`.
    tolerance : float, optional
        The penetration tolerance, in ``units``.

    Raises
    ------
    GeometryError
        Saying what to give.

    Examples
    --------
    >>> check_units("mm", -1.0)
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: tolerance -1.0: give a finite length of 0 or more, in the files' units
    """
    if units not in UNITS:
        raise GeometryError(f"units {units!r}: give one of {', '.join(UNITS)}")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance >= 0):
        raise GeometryError(f"tolerance {tolerance}: give a finite length of 0 or more, in the files' units")


def assembly_of(parts: tuple[PartShape, ...], units: str, tolerance: float | None) -> Assembly:
    """The parts as an assembly, with the penetration tolerance in metres (``tolerance`` in ``units``).

    Parameters
    ----------
    parts : tuple of PartShape
        The parts, in metres.
    units : str
        The files' unit of length (a key of :data:`UNITS`).
    tolerance : float, optional
        The penetration tolerance in ``units``; default: :data:`TOLERANCE_SHARE` of the assembly's size.

    Returns
    -------
    Assembly
        The assembly.

    Raises
    ------
    GeometryError
        Units not known, or a tolerance that is not a finite length of 0 or more.

    Examples
    --------
    >>> assembly_of((), "inch", None)
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: units 'inch': give one of m, mm
    """
    check_units(units, tolerance)
    if tolerance is None:
        boxes = np.vstack([p.bounds for p in parts])
        tol = TOLERANCE_SHARE * float(np.linalg.norm(boxes.max(axis=0) - boxes.min(axis=0)))
    else:
        tol = tolerance * UNITS[units]
    return Assembly(parts, tol, units)


def _mesh_files(folder: Path) -> list[tuple[str, Path]]:
    """The folder's mesh files as (part id, file), sorted by id; counted and sized before any is read."""
    if not folder.is_dir():
        raise GeometryError(f"{folder}: not a folder; give a folder of meshes, one file a part (.obj, .stl, .ply)")
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in SUFFIXES and not f.name.startswith("."))
    if not files:
        raise GeometryError(f"{folder}: no mesh file (.obj, .stl, .ply) in the folder")
    if len(files) > MAX_MESH_PARTS:
        raise GeometryError(f"{folder}: {len(files):,} mesh files; an assembly has at most {MAX_MESH_PARTS:,} parts: "
                            "derive subassemblies separately")
    seen: dict[str, Path] = {}
    for f in files:
        if f.stem in seen:
            raise GeometryError(f"part {f.stem!r}: two files ({seen[f.stem].name}, {f.name}); keep one file a part")
        if not f.stem or len(f.stem) > MAX_ID:
            raise GeometryError(f"{f.name}: a part id (the file's stem) has 1 to {MAX_ID} characters; rename the file")
        if not f.is_file():
            raise GeometryError(f"part {f.stem!r}: {f.name} is not a regular file")
        size = f.stat().st_size
        if size > MAX_MESH_BYTES:
            raise GeometryError(f"part {f.stem!r}: {f.name} has {size:,} bytes; a part's mesh has at most "
                                f"{MAX_MESH_BYTES:,} bytes: simplify the mesh")
        seen[f.stem] = f
    return sorted(seen.items())


def _read_part(part: str, file: Path, scale: float) -> PartShape:
    """One part's mesh, read and checked, as closed bodies in metres."""
    import trimesh

    try:
        mesh = trimesh.load(str(file), force="mesh", process=False)
        vertices = np.asarray(mesh.vertices, dtype=float)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except Exception as exc:   # the readers raise many kinds on a bad file: each is the same refusal
        raise GeometryError(f"part {part!r}: {file.name} is not a readable mesh ({type(exc).__name__}: "
                            f"{str(exc)[:200]!r}); export it again as OBJ, STL or PLY") from None
    try:
        bodies = mesh_bodies(part, vertices, faces, scale=scale, join=file.suffix.lower() == ".stl")
    except GeometryError as exc:    # the file named too: a part's id is its stem, the suffix tells files apart
        raise GeometryError(f"{file.name}: {exc}") from None
    return PartShape(part, file, bodies, len(faces))


def mesh_bodies(part: str, vertices: np.ndarray, faces: np.ndarray, *, scale: float = 1.0,
                join: bool = False) -> tuple[Body, ...]:
    """A mesh's closed convex bodies, checked: triangles, bounds, finite coordinates, then each body.

    Parameters
    ----------
    part : str
        The part's id (for the messages).
    vertices, faces : numpy.ndarray
        The mesh: ``(n, 3)`` coordinates and ``(m, 3)`` vertex indices.
    scale : float
        Metres per unit of the coordinates.
    join : bool
        Join vertices at one position before the bodies are found (STL, glTF and MJCF meshes repeat
        them); else a body is a piece whose triangles share vertices.

    Returns
    -------
    tuple of Body
        The bodies, in metres.

    Raises
    ------
    GeometryError
        No triangle, over :data:`~opportune.limits.MAX_TRIANGLES`, an index out of range, a coordinate not
        finite or farther than :data:`~opportune.limits.MAX_COORDINATE` from the origin, a degenerate triangle, or a body open, inside out in places or crossing itself: the message names the part.

    Examples
    --------
    >>> mesh_bodies("p", np.zeros((3, 3)), np.zeros((0, 3), int))
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: part 'p': no triangle; give the part's closed surface
    """
    if faces.ndim != 2 or len(faces) == 0 or faces.shape[1] != 3:
        raise GeometryError(f"part {part!r}: no triangle; give the part's closed surface")
    if len(faces) > MAX_TRIANGLES:
        raise GeometryError(f"part {part!r}: {len(faces):,} triangles; a part has at most {MAX_TRIANGLES:,}: "
                            "simplify the mesh")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise GeometryError(f"part {part!r}: a triangle names a vertex the file does not have")
    if not np.isfinite(vertices).all():
        row = int(np.nonzero(~np.isfinite(vertices).all(axis=1))[0][0])
        raise GeometryError(f"part {part!r}: vertex {row + 1} has a coordinate that is not a finite number")
    vertices = vertices * scale
    far = np.abs(vertices).max(axis=1) > MAX_COORDINATE
    if far.any():
        row = int(np.nonzero(far)[0][0])
        raise GeometryError(f"part {part!r}: vertex {row + 1} is {float(np.abs(vertices[row]).max()):.3g} m from the "
                            f"origin along an axis; an assembly lies within {MAX_COORDINATE:,} m of it: check the "
                            "units (--units) or move the model")
    return _bodies(part, vertices, faces, join)


def _bodies(part: str, vertices: np.ndarray, faces: np.ndarray, stl: bool) -> tuple[Body, ...]:
    """The part's bodies, each checked closed.  A body is a piece whose triangles share the
    file's vertices (an OBJ or PLY file writes each body with its own vertices, so that bodies touching
    along a face stay apart); an STL file has no shared vertices, so there they are joined by position."""
    if stl:
        vertices, faces = _merged(vertices, faces)
    corners = vertices[faces]
    normals_long = cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area2 = np.linalg.norm(normals_long, axis=1)
    longest = max(float(np.ptp(vertices[np.unique(faces)], axis=0).max()), 1e-300)
    bad = np.nonzero(area2 <= 1e-12 * longest * longest)[0]
    if len(bad):
        raise GeometryError(f"part {part!r}: triangle {int(bad[0]) + 1} is degenerate (no area: two corners at one "
                            f"point or all three on a line); {len(bad)} such triangle(s): repair the mesh")
    normals = normals_long / area2[:, None]
    labels = _components(len(vertices), faces)
    bodies = []
    for label in np.unique(labels[faces[:, 0]]):
        mine = labels[faces[:, 0]] == label
        points, tri = _merged(vertices, faces[mine])
        body = _body(part, len(bodies) + 1, points, tri, normals[mine])
        _check_not_crossing(part, len(bodies) + 1, body, np.nonzero(mine)[0])
        bodies.append(body)
    return tuple(bodies)


def _merged(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices at one position made one (files repeat them), with the faces renumbered."""
    _, inverse = np.unique(np.round(vertices, 12), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    points = np.zeros((inverse.max() + 1, 3))
    points[inverse] = vertices
    return points, inverse[faces]


def _components(n: int, tri: np.ndarray) -> np.ndarray:
    """A label per vertex: vertices joined by triangles share it (union-find)."""
    parent = np.arange(n)

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b, c in tri.tolist():
        ra, rb, rc = find(a), find(b), find(c)
        parent[rb] = ra
        parent[rc] = ra
    return np.array([find(i) for i in range(n)])


def _body(part: str, k: int, points: np.ndarray, tri: np.ndarray, normals: np.ndarray) -> Body:
    """One connected piece, checked closed (every edge in exactly two triangles, once each way); convex
    when every vertex is on the inner side of every face's plane, else checked a valid manifold; its
    normals and triangles made outward."""
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    keys = {tuple(e) for e in directed.tolist()}
    if len(keys) != len(directed) or any((b, a) not in keys for a, b in keys):
        raise GeometryError(f"part {part!r}: body {k} is not a closed surface (an edge without its opposite "
                            "triangle, or triangles facing opposite ways); close and orient the mesh")
    used = np.unique(tri)
    verts = points[used]
    corners = points[tri]
    # the signed volume says whether the triangles face out; inward-facing files are turned
    volume = float(np.einsum("ij,ij->i", corners[:, 0], cross(corners[:, 1], corners[:, 2])).sum()) / 6
    if volume < 0:
        normals = -normals
    size = max(float(np.ptp(verts, axis=0).max()), 1e-300)
    offsets = np.einsum("ij,ij->i", normals, corners[:, 0])
    outside = verts @ normals.T - offsets[None, :]
    renumber = np.zeros(len(points), dtype=np.int64)
    renumber[used] = np.arange(len(used))
    triangles = renumber[tri][:, [0, 2, 1]] if volume < 0 else renumber[tri]
    edges = points[directed[:, 1]] - points[directed[:, 0]]
    convex = bool(outside.max() <= 1e-9 * size)
    body = Body(verts, _unique_directions(normals), _unique_directions(edges), triangles, convex)
    if not convex:
        from opportune.derive.solids import solid

        try:
            solid(body)
        except ValueError as exc:
            raise GeometryError(f"part {part!r}: body {k} is not convex and not a valid solid ({exc}); repair the "
                                "mesh (closed, oriented, not crossing itself) or write it as convex bodies") from None
    return body


def _check_not_crossing(part: str, k: int, body: Body, numbers: np.ndarray) -> None:
    """Refuse a body whose triangles cross or overlap each other (a surface through itself: its inside is
    not defined, for the separating axes or for the booleans).  ``numbers`` are the body's triangles'
    indices in the file (for the message).

    A convex body's triangles all lie on its hull, facing out, so their signed volume is the hull's volume
    times how often they cover it: once unless they overlap (compared with manifold3d's hull, O(n log n)).
    A body that is not convex is searched by libigl's exact predicates over a tree of bounding boxes, to
    the first crossing pair (triangles sharing an edge or a corner and only touching there do not cross);
    its worst case, triangles whose boxes all overlap, is quadratic in the triangles, bounded by
    :data:`~opportune.limits.MAX_TRIANGLES` and well below the booleans' own cost on such a body."""
    triangles = np.ascontiguousarray(body.triangles, dtype=np.int64)
    if body.convex:
        import manifold3d

        corners = body.vertices[triangles]
        volume = float(np.einsum("ij,ij->i", corners[:, 0], cross(corners[:, 1], corners[:, 2])).sum()) / 6
        hull = manifold3d.Manifold.hull_points(np.ascontiguousarray(body.vertices - body.vertices[0])).volume()
        if volume > 1.5 * hull:     # an integer multiple of the hull: 2 or more is a surface over itself
            raise GeometryError(f"part {part!r}: body {k} crosses itself (its triangles cover its hull "
                                f"{volume / hull:.0f} times over); {_REPAIR}")
        return
    from igl.predicates import find_self_intersections

    found, pairs, _ = find_self_intersections(body.vertices, triangles, True)
    if found:
        a, b = sorted(int(numbers[i]) + 1 for i in pairs[0])
        raise GeometryError(f"part {part!r}: body {k} crosses itself (its triangles {a} and {b} intersect, as "
                            f"read from the file); {_REPAIR}")


#: What a message on a body that crosses itself asks for.
_REPAIR = ("repair the mesh (a closed surface that does not pass through itself) or write the part as separate "
           "closed bodies")


def _unique_directions(vectors: np.ndarray) -> np.ndarray:
    """Unit vectors, each line once (a direction and its opposite are one axis)."""
    units = vectors / np.linalg.norm(vectors, axis=1)[:, None]
    # one sign per line: the first non-zero coordinate positive
    first = np.argmax(np.abs(units) > 1e-12, axis=1)
    sign = np.sign(units[np.arange(len(units)), first])
    units = units * sign[:, None]
    _, index = np.unique(np.round(units, 9), axis=0, return_index=True)
    return units[np.sort(index)]
