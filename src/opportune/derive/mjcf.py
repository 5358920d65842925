"""An assembly read from a MuJoCo MJCF model: each named body with geoms is a part.

Unnamed bodies join their nearest named ancestor; each geom is taken in its world pose: meshes as they
are, boxes, cylinders, spheres, ellipsoids and capsules meshed (:data:`CYLINDER_SECTIONS`,
:data:`SPHERE_SUBDIVISIONS`).  Planes and geoms that collide with nothing (drawn only) are left out.

The XML is checked first with expat (:func:`scan_mjcf`: no DTD or entity, bounded bytes, elements,
nesting, includes, bodies and geoms, no element that multiplies bodies, mesh files sized).  Then:

* with MuJoCo installed (the ``physics`` extra), MuJoCo compiles the model (``mujoco.MjSpec``, every
  texture replaced by one pixel, so that only geometry is built) and the geoms' world poses are its own;
* without it, the checked XML tree is read here (:func:`read_mjcf_xml`): bodies and primitive geoms with
  ``pos``, ``quat``, ``axisangle``, ``euler`` (the compiler's ``angle`` and ``eulerseq``), ``xyaxes``,
  ``zaxis`` and ``fromto``, as MuJoCo reads them.  What needs MuJoCo's compiler (defaults and classes,
  frames, mesh geoms) is refused, saying to install it.  A test compares the two readers.
"""

from __future__ import annotations

from pathlib import Path
from xml.parsers import expat

import numpy as np

from opportune.derive.geometry import UNITS, Assembly, GeometryError, PartShape, assembly_of, check_units, mesh_bodies
from opportune.derive.scene import file_bytes, id_problem, shown
from opportune.limits import (MAX_GEOMS, MAX_INCLUDE_DEPTH, MAX_MESH_BYTES, MAX_MJCF_BODIES, MAX_SCENE_DEPTH,
                              MAX_TRIANGLES, MAX_XML_BYTES, MAX_XML_ELEMENTS)

#: A cylinder or a capsule is meshed as a prism (a capsule: with hemispheres) of this many sides, inscribed
#: in the true shape: 32 sides stay within 0.5 % of the radius.
CYLINDER_SECTIONS = 32
#: Spheres and ellipsoids are meshed as an icosphere subdivided this many times (320 triangles).
SPHERE_SUBDIVISIONS = 2
#: Elements refused: they multiply bodies after the count (replicate, composite, flexcomp), or load data
#: no part's shape needs (height fields, skins, flexes, other models, plugins).
_REFUSED = frozenset({"replicate", "composite", "flexcomp", "flex", "hfield", "skin", "attach", "model",
                      "plugin", "extension", "instance"})
#: The primitive geom types, as MuJoCo names them (a geom's type defaults to sphere).
PRIMITIVES = ("box", "cylinder", "capsule", "sphere", "ellipsoid")


def read_mjcf_assembly(path: str | Path, *, units: str = "m", tolerance: float | None = None,
                       use_mujoco: bool | None = None) -> Assembly:
    """Read an MJCF model in the assembled pose.

    Parameters
    ----------
    path : str or Path
        The model (``.xml`` or ``.mjcf``).
    units : str
        ``"m"`` (default) or ``"mm"``: the model's unit of length.
    tolerance : float, optional
        The penetration tolerance in the model's units (default: a millionth of the assembly's size).
    use_mujoco : bool, optional
        Compile with MuJoCo (True), read the XML here (False); default: MuJoCo if it is installed.

    Returns
    -------
    Assembly
        The parts (named bodies), sorted by id, in metres.

    Raises
    ------
    GeometryError
        A model over its bounds, malformed, refused by MuJoCo, or holding an unusable geom: the message
        names the file (and the body) and says what to do.

    Examples
    --------
    >>> read_mjcf_assembly("missing.xml")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: missing.xml is not a regular file; give an MJCF file as a file
    """
    check_units(units, tolerance)
    path = Path(path)
    tree = scan_mjcf(path)
    if use_mujoco is None:
        import importlib.util

        use_mujoco = importlib.util.find_spec("mujoco") is not None
    pieces = _compiled(path) if use_mujoco else read_mjcf_xml(path, tree)
    parts = []
    for part, items in sorted(pieces.items()):
        triangles = sum(len(f) for _, f in items)
        if triangles > MAX_TRIANGLES:
            raise GeometryError(f"{shown(path.name)}: body {part!r} has {triangles:,} triangles; a part has at "
                                f"most {MAX_TRIANGLES:,}: simplify its meshes")
        bodies = [b for v, f in items for b in mesh_bodies(part, v, f, scale=UNITS[units], join=True)]
        parts.append(PartShape(part, path, tuple(bodies), triangles))
    if not parts:
        raise GeometryError(f"{shown(path.name)}: no part (no named body with a geom); name each part's body")
    return assembly_of(tuple(parts), units, tolerance)


def primitive_mesh(kind: str, size) -> tuple[np.ndarray, np.ndarray]:
    """A primitive geom's surface in its own frame, as MuJoCo sizes it (half-lengths, radii).

    Parameters
    ----------
    kind : str
        One of :data:`PRIMITIVES`.
    size : sequence of float
        MuJoCo's ``size``: box ``[x, y, z]`` half-sizes; cylinder and capsule ``[radius, half-length]``;
        sphere ``[radius]``; ellipsoid ``[a, b, c]``.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Vertices and triangles (a closed convex surface).

    Examples
    --------
    >>> v, f = primitive_mesh("box", [0.5, 1.0, 1.5])
    >>> v.min(axis=0).tolist(), len(f)
    ([-0.5, -1.0, -1.5], 12)
    """
    import trimesh.creation as make

    size = np.asarray(size, dtype=float)
    if kind == "box":
        mesh = make.box(extents=2 * size[:3])
    elif kind == "cylinder":
        mesh = make.cylinder(radius=size[0], height=2 * size[1], sections=CYLINDER_SECTIONS)
    elif kind == "capsule":
        mesh = make.capsule(height=2 * size[1], radius=size[0], count=[CYLINDER_SECTIONS // 2] * 2)
    else:
        mesh = make.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=1.0)
        mesh.apply_scale(size[:3] if kind == "ellipsoid" else size[0])
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


# ---------------------------------------------------------------- compiled by MuJoCo


def _compiled(path: Path) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Each part's geoms in world pose, as MuJoCo compiles the model."""
    import mujoco

    try:
        spec = mujoco.MjSpec.from_file(str(path))
        for t in spec.textures:    # only geometry is wanted: a texture's pixels (a file, or a huge builtin) never
            t.file, t.content_type, t.cubefiles = "", "", [""] * 6
            t.builtin, t.type, t.width, t.height = mujoco.mjtBuiltin.mjBUILTIN_FLAT, mujoco.mjtTexture.mjTEXTURE_2D, 1, 1
        model = spec.compile()
    except Exception as exc:   # MuJoCo reports every problem of a model as one kind of error, with its line
        raise GeometryError(f"{shown(path.name)}: MuJoCo refuses the model: "
                            f"{shown(' '.join(str(exc).split())[:300])}; fix the model") from None
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    owner = _body_owners(model, shown(path.name))
    names = {int(getattr(mujoco.mjtGeom, f"mjGEOM_{k.upper()}")): k for k in PRIMITIVES + ("mesh", "plane")}
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for k in range(model.ngeom):
        kind = names.get(int(model.geom_type[k]), "other")
        if kind == "plane" or not (model.geom_contype[k] or model.geom_conaffinity[k]):
            continue   # an infinite floor is no part; a geom that collides with nothing is only drawn
        part = owner[int(model.geom_bodyid[k])]
        label = repr(model.geom(k).name) if model.geom(k).name else str(k)
        if part is None:
            raise GeometryError(f"{shown(path.name)}: geom {label} is in the worldbody or an unnamed body under "
                                "it; put it in a named body (a part)")
        if kind == "mesh":
            m = int(model.geom_dataid[k])
            va, vn, fa, fn = (int(x[m]) for x in (model.mesh_vertadr, model.mesh_vertnum, model.mesh_faceadr,
                                                   model.mesh_facenum))
            local = np.array(model.mesh_vert[va:va + vn], dtype=float)
            faces = np.array(model.mesh_face[fa:fa + fn], dtype=np.int64)
        elif kind in PRIMITIVES:
            local, faces = primitive_mesh(kind, model.geom_size[k])
        else:
            raise GeometryError(f"{shown(path.name)}: body {part!r}: geom {label} is of a type not read (height "
                                "field or SDF); give it as a mesh")
        with np.errstate(all="ignore"):   # huge sizes: the vertices' bound refuses them
            world = local @ data.geom_xmat[k].reshape(3, 3).T + data.geom_xpos[k]
        pieces.setdefault(part, []).append((world, faces))
    return pieces


def _body_owners(model, file: str) -> list[str | None]:
    """For each body, its part: its name, or its nearest named ancestor's; None in the worldbody."""
    owner: list[str | None] = [None]
    for b in range(1, model.nbody):
        name = model.body(b).name
        if name and id_problem(name):
            raise GeometryError(f"{file}: body {b}'s name {id_problem(name)}; rename the body")
        owner.append(name if name else owner[int(model.body_parentid[b])])
    return owner


# ---------------------------------------------------------------- read here, without MuJoCo


def read_mjcf_xml(path: Path, tree: dict) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Each part's geoms in world pose, read from the checked XML tree without MuJoCo.

    Parameters
    ----------
    path : Path
        The model (for the messages).
    tree : dict
        Its root element with includes in place (:func:`scan_mjcf`).

    Returns
    -------
    dict
        For each part, its geoms as ``(vertices, triangles)`` in world coordinates.

    Raises
    ------
    GeometryError
        An element or attribute this reader does not follow (defaults, classes, frames, mesh geoms: install
        MuJoCo), a number that is not one, or a geom in the worldbody.

    Examples
    --------
    >>> tree = {"tag": "mujoco", "attrs": {}, "children": [{"tag": "worldbody", "attrs": {}, "children": [
    ...     {"tag": "body", "attrs": {"name": "a", "pos": "1 0 0"}, "children": [
    ...         {"tag": "geom", "attrs": {"type": "box", "size": "1 1 1"}, "children": []}]}]}]}
    >>> v, f = read_mjcf_xml(Path("m.xml"), tree)["a"][0]
    >>> v.min(axis=0).tolist()
    [0.0, -1.0, -1.0]
    """
    name = shown(path.name)
    compiler = {"angle": "degree", "eulerseq": "xyz"}
    for element in _walk(tree):
        if element["tag"] in ("default", "frame") or {"class", "childclass"} & set(element["attrs"]):
            raise GeometryError(f"{name}: <{element['tag']}> with defaults, classes or frames needs MuJoCo's compiler: "
                                "pip install 'opportune[geometry,physics]'")
        if element["tag"] == "compiler":
            compiler.update({k: v for k, v in element["attrs"].items() if k in compiler})
    if compiler["angle"] not in ("degree", "radian") or len(compiler["eulerseq"]) != 3 or \
            set(compiler["eulerseq"].lower()) - set("xyz"):
        raise GeometryError(f"{name}: <compiler angle=... eulerseq=...> not read; fix the model")
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for world in (c for c in tree["children"] if c["tag"] == "worldbody"):
        _body(name, world, np.eye(3), np.zeros(3), None, compiler, pieces, top=True)
    return pieces


def _walk(element: dict):
    yield element
    for c in element["children"]:
        yield from _walk(c)


def _body(name: str, body: dict, rot: np.ndarray, pos: np.ndarray, part: str | None, compiler: dict,
          pieces: dict, top: bool = False) -> None:
    """A body's geoms in world pose (``rot``, ``pos``: its frame), then its children's."""
    if not top:
        own = body["attrs"].get("name")
        if own and id_problem(own):
            raise GeometryError(f"{name}: a body's name {id_problem(own)}; rename the body")
        part = own or part
    for child in body["children"]:
        if child["tag"] == "body":
            with np.errstate(all="ignore"):
                r, p = _pose(name, child["attrs"], compiler)
            if not np.isfinite(r).all():
                raise GeometryError(f"{name}: a body's orientation is degenerate (a zero vector); fix it")
            _body(name, child, rot @ r, pos + rot @ p, part, compiler, pieces)
        elif child["tag"] == "geom":
            a = child["attrs"]
            kind = a.get("type", "sphere")
            if kind == "plane" or (a.get("contype", "1").strip() == "0" and a.get("conaffinity", "1").strip() == "0"):
                continue
            if kind not in PRIMITIVES:
                raise GeometryError(f"{name}: a {shown(kind[:40])} geom needs MuJoCo's compiler (mesh geoms and "
                                    "others): pip install 'opportune[geometry,physics]'")
            if part is None:
                raise GeometryError(f"{name}: a geom is in the worldbody or an unnamed body under it; put it in a "
                                    "named body (a part)")
            with np.errstate(all="ignore"):   # a zero vector or quaternion: refused below, without a warning
                size, r, p = _geom_frame(name, a, kind, compiler)
            if not (np.isfinite(r).all() and np.isfinite(size).all()):
                raise GeometryError(f"{name}: a geom's orientation or fromto is degenerate (a zero vector); fix it")
            local, faces = primitive_mesh(kind, size)
            with np.errstate(all="ignore"):
                pieces.setdefault(part, []).append((local @ (rot @ r).T + pos + rot @ p, faces))


def _numbers(name: str, attrs: dict, key: str, count: int, default=None) -> np.ndarray:
    """An attribute of ``count`` finite numbers (or up to, for ``size``), or ``default`` when absent."""
    if key not in attrs:
        return None if default is None else np.array(default, dtype=float)
    try:
        values = np.array([float(x) for x in attrs[key].split()], dtype=float)
    except ValueError:
        values = np.array([np.nan])
    if not (1 <= len(values) <= count if key == "size" else len(values) == count) or not np.isfinite(values).all():
        raise GeometryError(f"{name}: {key}={shown(attrs[key][:60])!r} is not {count} finite numbers; fix the model")
    return values


def _pose(name: str, attrs: dict, compiler: dict) -> tuple[np.ndarray, np.ndarray]:
    """A body's or geom's frame in its parent's: a rotation and a position."""
    pos = _numbers(name, attrs, "pos", 3, [0, 0, 0])
    given = [k for k in ("quat", "axisangle", "euler", "xyaxes", "zaxis") if k in attrs]
    if len(given) > 1:
        raise GeometryError(f"{name}: both {given[0]} and {given[1]} give one orientation; keep one")
    scale = np.pi / 180 if compiler["angle"] == "degree" else 1.0
    if not given:
        return np.eye(3), pos
    key = given[0]
    v = _numbers(name, attrs, key, {"quat": 4, "axisangle": 4, "euler": 3, "xyaxes": 6, "zaxis": 3}[key])
    if key == "quat":
        return _quat_matrix(v), pos
    if key == "axisangle":
        return _axis_angle(v[:3], v[3] * scale), pos
    if key == "zaxis":
        return _z_to(v), pos
    if key == "xyaxes":
        x = v[:3] / np.linalg.norm(v[:3])
        y = v[3:] - (v[3:] @ x) * x
        y = y / np.linalg.norm(y)
        return np.column_stack([x, y, np.cross(x, y)]), pos
    r = np.eye(3)
    for axis, angle in zip(compiler["eulerseq"], v * scale):
        step = _axis_angle(np.eye(3)["xyz".index(axis.lower())], angle)
        r = r @ step if axis.islower() else step @ r    # lower case: the moving frame's axes
    return r, pos


def _geom_frame(name: str, a: dict, kind: str, compiler: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A geom's size, rotation and position; ``fromto`` sets the last two and the half-length."""
    size = _numbers(name, a, "size", 3, [0, 0, 0])
    if "fromto" not in a:
        r, p = _pose(name, a, compiler)
        return size, r, p
    ends = _numbers(name, a, "fromto", 6)
    axis = ends[:3] - ends[3:]      # MuJoCo turns +z towards "from" (it matters to a prism's sides)
    half = np.linalg.norm(axis) / 2
    size = np.array([size[0], half, 0]) if kind in ("cylinder", "capsule") else np.array([size[0], size[1], half])
    return size, _z_to(axis), (ends[:3] + ends[3:]) / 2


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    half = angle / 2
    return _quat_matrix(np.concatenate([[np.cos(half)], np.sin(half) * axis]))


def _z_to(v: np.ndarray) -> np.ndarray:
    """The least rotation taking +z to ``v`` (as MuJoCo's ``mju_quatZ2Vec``; opposite: half a turn about x)."""
    v = v / np.linalg.norm(v)
    axis = np.cross([0.0, 0.0, 1.0], v)
    s = np.linalg.norm(axis)
    if s < 1e-10:
        return np.eye(3) if v[2] > 0 else _axis_angle(np.array([1.0, 0.0, 0.0]), np.pi)
    return _axis_angle(axis / s, float(np.arctan2(s, v[2])))


# ---------------------------------------------------------------- the checks before either reader


def scan_mjcf(path: Path) -> dict:
    """Check an MJCF file and its includes before anything reads them, and return its element tree.

    Each file's bytes and all of them, no DTD or entity, the elements and their nesting, the includes'
    depth, the bodies and geoms, no element that multiplies bodies, and every mesh file a regular file of
    at most :data:`~opportune.limits.MAX_MESH_BYTES`.

    Parameters
    ----------
    path : Path
        The model.

    Returns
    -------
    dict
        The root element ``{"tag", "attrs", "children"}``, each ``<include>`` replaced by the included
        file's elements.

    Raises
    ------
    GeometryError
        Naming the file (and the line) and what to do.

    Examples
    --------
    >>> scan_mjcf(Path("missing.xml"))
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: missing.xml is not a regular file; give an MJCF file as a file
    """
    counts = {"element": 0, "body": 0, "geom": 0, "bytes": 0}
    meshdirs: list[str] = []
    meshes: list[str] = []
    root = _scan_xml(path, path.parent, 0, counts, meshdirs, meshes)
    for file in meshes:
        file_bytes(path.parent / (meshdirs[-1] if meshdirs else "") / file, MAX_MESH_BYTES, "a part's mesh file", path)
    return root


def _scan_xml(path: Path, home: Path, depth: int, counts: dict, meshdirs: list, meshes: list,
              source: Path | None = None) -> dict:
    """One XML file of the model (``depth`` includes down), scanned with expat into a tree."""
    name = shown(path.name)
    raw = file_bytes(path, MAX_XML_BYTES, "an MJCF file", source)
    counts["bytes"] += len(raw)
    if counts["bytes"] > MAX_XML_BYTES:
        raise GeometryError(f"{name}: the model and its includes have more than {MAX_XML_BYTES:,} bytes in all; "
                            "split the assembly")
    parser = expat.ParserCreate()
    top: dict = {"tag": "", "attrs": {}, "children": []}
    stack = [top]
    includes: list[tuple[dict, str]] = []

    def refuse(*_args):
        raise GeometryError(f"{name}: line {parser.CurrentLineNumber}: the file declares a DTD or entities; remove "
                            "the <!DOCTYPE ...> and <!ENTITY ...> declarations: MJCF needs none")

    def start(tag, attrs):
        counts["element"] += 1
        if counts["element"] > MAX_XML_ELEMENTS or len(stack) > MAX_SCENE_DEPTH:
            raise GeometryError(f"{name}: line {parser.CurrentLineNumber}: more than {MAX_XML_ELEMENTS:,} elements "
                                f"or nested more than {MAX_SCENE_DEPTH} deep; split the assembly")
        if tag in _REFUSED:
            raise GeometryError(f"{name}: line {parser.CurrentLineNumber}: <{shown(tag)}> is not read (it multiplies "
                                "bodies or loads data no part's shape needs); expand or remove it")
        if tag in ("body", "geom"):
            counts[tag] += 1
            most = MAX_MJCF_BODIES if tag == "body" else MAX_GEOMS
            if counts[tag] > most:
                raise GeometryError(f"{name}: more than {most:,} <{tag}> elements; an MJCF assembly has at most "
                                    f"{most:,}: derive subassemblies separately")
        element = {"tag": tag, "attrs": attrs, "children": []}
        stack[-1]["children"].append(element)
        stack.append(element)
        if tag == "include":
            includes.append((element, attrs.get("file", "")))
        elif tag == "mesh" and "file" in attrs:
            meshes.append(attrs["file"])
        elif tag == "compiler" and ("meshdir" in attrs or "assetdir" in attrs):
            meshdirs.append(attrs.get("meshdir", attrs.get("assetdir")))

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    try:
        parser.Parse(raw, True)
    except expat.ExpatError as exc:
        raise GeometryError(f"{name}: not XML ({shown(str(exc))}); fix the file") from None
    for element, file in includes:
        if depth + 1 > MAX_INCLUDE_DEPTH:
            raise GeometryError(f"{name}: includes nested more than {MAX_INCLUDE_DEPTH} deep (or an include of "
                                "itself); flatten the includes")
        included = _scan_xml(home / file, home, depth + 1, counts, meshdirs, meshes, path)
        element["tag"], element["children"] = "included", included["children"]
    return _flatten(top["children"][0])


def _flatten(element: dict) -> dict:
    """The tree with each included file's elements in the place of its ``<include>``."""
    children = []
    for c in element["children"]:
        children.extend(_flatten(c)["children"] if c["tag"] == "included" else [_flatten(c)])
    return {"tag": element["tag"], "attrs": element["attrs"], "children": children}
