"""An assembly read from one scene file: a glTF/GLB scene, a MuJoCo MJCF model or a STEP file.

* **glTF / GLB**: each named node that carries a mesh is a part (its id the node's name); nodes without
  a name join their nearest named ancestor (a part drawn as several meshes); world transforms are
  applied.  The file is read by this module, not handed to a loader whole: its JSON is checked first
  (nodes, depth, buffers' bytes, each part's triangles, all against :mod:`opportune.limits`), then only
  the positions and indices of the parts' triangles are decoded.  Materials and images are never read.
* **MJCF**: each named body with geoms is a part (unnamed bodies join their nearest named ancestor);
  its geoms in their world pose: meshes as they are, boxes, cylinders, spheres, ellipsoids and capsules
  meshed (:data:`CYLINDER_SECTIONS`).  The XML is checked first with expat (no DTD or entity, bounded
  bytes, elements, depth, includes, bodies and geoms; mesh files sized), then compiled by MuJoCo
  (``mujoco.MjSpec``) with textures replaced by one pixel, so that only geometry is built.
* **STEP** (the ``step`` extra): meshed by Open CASCADE through cascadio in a child process bounded in
  time and memory (:data:`~opportune.limits.STEP_SECONDS`, :data:`~opportune.limits.STEP_MEMORY`), then
  read as a GLB scene whose parts are the STEP products.

A mesh's vertices at one position are joined (exporters repeat them along sharp edges), then each
connected piece is a closed convex body (:func:`opportune.derive.geometry.mesh_bodies`): a part that is
not convex gives each convex piece its own primitive, node, geom or mesh.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from pathlib import Path
from xml.parsers import expat

import numpy as np

from opportune.derive.geometry import UNITS, Assembly, GeometryError, PartShape, assembly_of, check_units, mesh_bodies
from opportune.limits import (MAX_GEOMS, MAX_ID, MAX_INCLUDE_DEPTH, MAX_MESH_BYTES, MAX_MESH_PARTS, MAX_MJCF_BODIES,
                              MAX_SCENE_BYTES, MAX_SCENE_DEPTH, MAX_SCENE_NODES, MAX_STEP_BYTES, MAX_TRIANGLES,
                              MAX_XML_BYTES, MAX_XML_ELEMENTS, STEP_MEMORY, STEP_SECONDS)

#: A cylinder or a capsule of an MJCF file is meshed as a prism (a capsule: with hemispheres) of this many
#: sides, inscribed in the true shape: 32 sides stay within 0.5 % of the radius.
CYLINDER_SECTIONS = 32
#: Spheres and ellipsoids are meshed as an icosphere subdivided this many times (320 triangles).
SPHERE_SUBDIVISIONS = 2
#: glTF accessor component types read: for positions ``float32``; for indices unsigned integers.
_COMPONENTS = {5126: np.dtype("<f4"), 5121: np.dtype("u1"), 5123: np.dtype("<u2"), 5125: np.dtype("<u4")}
#: MJCF elements refused: they multiply bodies after the count (replicate, composite, flexcomp), or load
#: data no geometry needs (height fields, skins, flexes, other models, plugins).
_MJCF_REFUSED = frozenset({"replicate", "composite", "flexcomp", "flex", "hfield", "skin", "attach", "model",
                           "plugin", "extension", "instance"})


def read_scene_assembly(path: str | Path, *, units: str = "m", tolerance: float | None = None) -> Assembly:
    """Read a glTF/GLB scene or an MJCF model in the assembled pose.

    Parameters
    ----------
    path : str or Path
        A ``.glb``, ``.gltf``, ``.xml`` or ``.mjcf`` file.
    units : str
        ``"m"`` (default) or ``"mm"``: the file's unit of length.
    tolerance : float, optional
        The penetration tolerance in the file's units (default: a millionth of the assembly's size).

    Returns
    -------
    Assembly
        The parts, in metres.

    Raises
    ------
    GeometryError
        As :func:`read_scene`, or units or a tolerance not known.

    Examples
    --------
    >>> read_scene_assembly("missing.xml", units="inch")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: units 'inch': give one of m, mm
    """
    check_units(units, tolerance)
    return assembly_of(read_scene(Path(path), UNITS[units]), units, tolerance)


def read_scene(path: Path, scale: float) -> tuple[PartShape, ...]:
    """The parts of a glTF/GLB scene, an MJCF model or a STEP file, sorted by id, in metres.

    Parameters
    ----------
    path : Path
        A ``.glb``, ``.gltf``, ``.xml``, ``.mjcf``, ``.step`` or ``.stp`` file.
    scale : float
        Metres per unit of the file's coordinates (not used for STEP, whose files carry their unit).

    Returns
    -------
    tuple of PartShape
        The parts.

    Raises
    ------
    GeometryError
        A file over its bounds, malformed, or holding an unusable mesh: the message names the file (and
        the node, body or part) and says what to do.

    Examples
    --------
    >>> read_scene(Path("missing.glb"), 1.0)
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: missing.glb: not a file; give a glTF/GLB scene or an MJCF model
    """
    if not path.is_file():
        raise GeometryError(f"{_shown(path.name)}: not a file; give a glTF/GLB scene or an MJCF model")
    if path.suffix.lower() in (".glb", ".gltf"):
        try:
            parts = _read_gltf(path, scale)
        except GeometryError:
            raise
        except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
            # the JSON is the file's: a value of a kind no check above foresaw is the same refusal
            raise GeometryError(f"{_shown(path.name)}: not a glTF scene this reader follows ({type(exc).__name__}: "
                                f"{_shown(str(exc)[:120])}); export the scene again") from None
    elif path.suffix.lower() in (".step", ".stp"):
        parts = _read_step(path)
    else:
        parts = _read_mjcf(path, scale)
    if not parts:
        raise GeometryError(f"{_shown(path.name)}: no part (no named node or body with a mesh or geom); name "
                            "each part's node or body")
    return tuple(sorted(parts, key=lambda p: p.id))


def _bad_id(name: str) -> str:
    """What is wrong with a node's or body's name as a part id: too long or holding a control character
    (a part id reaches terminals and plan files); ``""`` when nothing is."""
    if len(name) > MAX_ID:
        return f"has {len(name):,} characters; a part id has at most {MAX_ID}"
    if not name.isprintable():
        return f"{name!r} holds a control character; a part id is printable text"
    return ""


def _brief(value) -> str:
    """A value of the file for a message: its repr, cut short (a file may put a megabyte where a number goes)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _shown(text: str) -> str:
    """User text for a message: control characters escaped (never sent raw to a terminal)."""
    return text if text.isprintable() else repr(text)[1:-1]


def _bytes(path: Path, most: int, what: str, source: Path | None = None) -> bytes:
    """A regular file's bytes, its size checked before it is read (``source``: the file that names it)."""
    head = f"{_shown(source.name)}: " if source is not None else ""
    if not path.is_file():
        raise GeometryError(f"{head}{_shown(str(path))} is not a regular file; give {what} as a file")
    size = path.stat().st_size
    if size > most:
        raise GeometryError(f"{head}{_shown(path.name)}: {size:,} bytes; {what} has at most {most:,} bytes: split "
                            "the assembly or simplify its meshes")
    return path.read_bytes()


# ---------------------------------------------------------------- glTF and GLB


class _Gltf:
    """A glTF document being read: its JSON, the binary chunk of a GLB, the buffers decoded so far."""

    def __init__(self, path: Path, raw: bytes | None = None):
        self.path, self.name = path, _shown(path.name)
        raw = _bytes(path, MAX_SCENE_BYTES, "a scene file") if raw is None else raw
        self.bin = b""
        if raw[:4] == b"glTF":
            raw = self._glb(raw)
        try:
            self.doc = json.loads(raw)
        except (ValueError, RecursionError) as exc:
            self.fail(f"not glTF JSON ({type(exc).__name__}: {_shown(str(exc)[:120])})", "export the scene again")
        if not isinstance(self.doc, dict):
            self.fail("not glTF JSON (no object at the top)", "export the scene again")
        self.buffers: dict[int, bytes] = {}
        self.read = len(self.bin)

    def fail(self, what: str, hint: str):
        raise GeometryError(f"{self.name}: {what}; {hint}")

    def _glb(self, raw: bytes) -> bytes:
        """The JSON chunk of a GLB file; its binary chunk kept as buffer 0."""
        if len(raw) < 20:
            self.fail("a GLB file cut short", "export the scene again")
        (length,) = struct.unpack_from("<I", raw, 12)
        if raw[16:20] != b"JSON" or 20 + length > len(raw):
            self.fail("a GLB file whose first chunk is not its JSON", "export the scene again")
        rest = 20 + length + (-length % 4)
        if rest + 8 <= len(raw) and raw[rest + 4:rest + 8] == b"BIN\x00":
            (size,) = struct.unpack_from("<I", raw, rest)
            self.bin = raw[rest + 8:rest + 8 + size]
        return raw[20:20 + length]

    def items(self, key: str, most: int) -> list:
        """The document's list under ``key``, each item an object, at most ``most``."""
        value = self.doc.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            self.fail(f"'{key}' is not a list of objects", "export the scene again")
        if len(value) > most:
            self.fail(f"{len(value):,} {key}; a scene has at most {most:,}", "split the assembly into subassemblies")
        return value

    def buffer(self, k: int) -> bytes:
        """Buffer ``k``: the GLB's binary chunk, a ``data:`` URI, or a file beside the scene (by name only)."""
        if k in self.buffers:
            return self.buffers[k]
        buffers = self.items("buffers", MAX_SCENE_NODES)
        if not 0 <= k < len(buffers):
            self.fail(f"buffer {k} does not exist", "export the scene again")
        uri = buffers[k].get("uri")
        if uri is None:
            data = self.bin
        elif not isinstance(uri, str):
            self.fail(f"buffer {k} has a uri that is not text", "export the scene again")
        elif uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.partition(",")[2], validate=True)
            except ValueError:
                self.fail(f"buffer {k}'s data URI is not base64", "export the scene again")
        else:
            if os.path.basename(uri) != uri or uri in (".", "..") or "%" in uri or ":" in uri:
                self.fail(f"buffer {k} names {uri[:100]!r}, not a file beside the scene",
                          "keep the scene's .bin files in its folder, or export a single .glb")
            data = _bytes(self.path.parent / uri, MAX_SCENE_BYTES - self.read, "a scene's buffers in all", self.path)
        self.read += len(data) if uri is not None else 0
        if self.read > MAX_SCENE_BYTES:
            self.fail(f"buffers of more than {MAX_SCENE_BYTES:,} bytes in all", "split the assembly")
        self.buffers[k] = data
        return data

    def accessor(self, k, kind: str) -> np.ndarray:
        """Accessor ``k`` as an array: ``position`` (float VEC3) or ``index`` (unsigned SCALAR); every
        offset and length checked against its buffer view and buffer before the bytes are taken."""
        accessors, views = self.items("accessors", MAX_SCENE_NODES), self.items("bufferViews", MAX_SCENE_NODES)
        if not isinstance(k, int) or not 0 <= k < len(accessors):
            self.fail(f"accessor {_brief(k)} does not exist", "export the scene again")
        a = accessors[k]
        width = 3 if kind == "position" else 1
        dtype = _COMPONENTS.get(_int(a.get("componentType")))
        if ("sparse" in a or a.get("normalized") or a.get("type") != ("VEC3" if width == 3 else "SCALAR")
                or dtype is None or (kind == "position") != (dtype.kind == "f")):
            self.fail(f"accessor {k} ({kind}s) is sparse, normalized, compressed or of a type not read",
                      "export the scene with plain float positions and integer indices (no Draco, no quantization)")
        count, v = a.get("count"), a.get("bufferView")
        if not isinstance(count, int) or not isinstance(v, int) or not 0 <= v < len(views) or count < 0:
            self.fail(f"accessor {k} has no valid count or buffer view", "export the scene again")
        if count > 3 * MAX_TRIANGLES:    # a part's triangles are bounded, so are the rows read for one
            self.fail(f"accessor {k} has {count:,} {kind}s; a part's mesh has at most {3 * MAX_TRIANGLES:,}",
                      "simplify the mesh")
        view = views[v]
        item = dtype.itemsize * width
        numbers = [_int(view.get("byteOffset", 0)), _int(a.get("byteOffset", 0)), _int(view.get("byteLength", -1)),
                   _int(view.get("byteStride", item)), _int(view.get("buffer", -1))]
        if min(numbers) < 0:
            self.fail(f"accessor {k}'s buffer view has an offset, length, stride or buffer that is not a whole "
                      "number of 0 or more", "export the scene again")
        view_start, offset, length, stride, buffer = numbers
        start, end = view_start + offset, view_start + length
        data = self.buffer(buffer)
        if stride < item or start + stride * max(count - 1, 0) + item * (count > 0) > end or end > len(data):
            self.fail(f"accessor {k} reaches past its buffer view or buffer", "export the scene again")
        rows = np.ndarray((count, width), dtype=dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
        return np.array(rows, dtype=np.float64 if kind == "position" else np.int64)


def _int(value) -> int:
    """An offset, length or stride of a glTF file: a non-negative integer, else -1 (refused by its caller)."""
    return value if isinstance(value, int) and not isinstance(value, bool) and value >= 0 else -1


def _read_gltf(path: Path, scale: float, g: _Gltf | None = None) -> list[PartShape]:
    """The parts of a glTF or GLB scene: everything counted and bounded before any vertex is decoded."""
    g = _Gltf(path) if g is None else g
    owned = _gltf_parts(g)
    meshes = g.items("meshes", MAX_SCENE_NODES)
    for part, items in owned.items():
        triangles = 0
        for mesh, _ in items:
            for prim in _primitives(g, meshes, mesh):
                triangles += _triangles(g, prim)
        if triangles > MAX_TRIANGLES:
            raise GeometryError(f"{g.name}: part {part!r} has {triangles:,} triangles; a part has at most "
                                f"{MAX_TRIANGLES:,}: simplify its meshes")
    parts = []
    for part, items in owned.items():
        bodies = []
        for mesh, world in items:
            for prim in _primitives(g, meshes, mesh):
                vertices = g.accessor(prim["attributes"].get("POSITION"), "position")
                faces = (g.accessor(prim["indices"], "index") if "indices" in prim
                         else np.arange(len(vertices), dtype=np.int64)).reshape(-1, 3)
                with np.errstate(all="ignore"):
                    world_vertices = vertices @ world[:3, :3].T + world[:3, 3]
                bodies.extend(mesh_bodies(part, world_vertices, faces, scale=scale, join=True))
        parts.append(PartShape(part, path, tuple(bodies), sum(_triangles(g, p) for m, _ in items
                                                             for p in _primitives(g, meshes, m))))
    return parts


def _gltf_parts(g: _Gltf) -> dict[str, list[tuple[int, np.ndarray]]]:
    """Each part's meshes with their world transforms, walking the scene's node tree from its roots
    (depth, node count, one parent per node and unique part names checked on the way)."""
    nodes = g.items("nodes", MAX_SCENE_NODES)
    scenes = g.items("scenes", MAX_SCENE_NODES)
    k = g.doc.get("scene", 0)
    if isinstance(k, int) and 0 <= k < len(scenes):
        roots = scenes[k].get("nodes", [])
    else:   # no scene: every node that is no node's child
        children = {c for n in nodes for c in (n.get("children") or []) if isinstance(c, int)}
        roots = [n for n in range(len(nodes)) if n not in children]
    owned: dict[str, list[tuple[int, np.ndarray]]] = {}
    owner_node: dict[str, int] = {}     # each part's id: the node that names it
    seen: set[int] = set()
    stack = [(r, np.eye(4), None, -1, 1) for r in reversed(roots if isinstance(roots, list) else [])]
    while stack:
        n, parent, owner, named, depth = stack.pop()
        if not isinstance(n, int) or not 0 <= n < len(nodes) or n in seen:
            g.fail(f"node {_brief(n)} does not exist or has two parents", "export the scene again (a node tree)")
        if depth > MAX_SCENE_DEPTH:
            g.fail(f"nodes nested more than {MAX_SCENE_DEPTH} levels deep", "flatten the scene's hierarchy")
        seen.add(n)
        node = nodes[n]
        with np.errstate(all="ignore"):   # huge scales overflow: the vertices' bound refuses them, once
            world = parent @ _local(g, n, node)
        if isinstance(node.get("name"), str) and node["name"]:
            owner, named = node["name"], n
        if "mesh" in node:
            _own(g, n, owner, named, owner_node)
            owned.setdefault(owner, []).append((node["mesh"], world))
            if len(owned) > MAX_MESH_PARTS:
                g.fail(f"more than {MAX_MESH_PARTS:,} parts", "derive subassemblies separately")
        children = node.get("children", [])
        if not isinstance(children, list):
            g.fail(f"node {n}'s children are not a list", "export the scene again")
        stack.extend((c, world, owner, named, depth + 1) for c in reversed(children))
    return owned


def _own(g: _Gltf, n: int, owner: str | None, named: int, owner_node: dict[str, int]) -> None:
    """Check that node ``n``'s mesh has a part: a name (its own or an ancestor's), short, and one node's."""
    if owner is None:
        g.fail(f"node {n} carries a mesh but neither it nor an ancestor has a name",
               "name the node: its name is the part's id")
    bad = _bad_id(owner)
    if bad:
        g.fail(f"node {named}'s name {bad}", "rename the node")
    first = owner_node.setdefault(owner, named)
    if first != named:
        g.fail(f"two nodes ({first} and {named}) are named {owner!r}", "give each part's node its own "
               "name (identical parts: list them under quantities in the manifest)")


def _local(g: _Gltf, n: int, node: dict) -> np.ndarray:
    """A node's transform from its parent: its ``matrix``, or translation · rotation · scale."""
    try:
        given = [np.array(node[k], dtype=float).reshape(size) for k, size in
                 (("matrix", 16), ("translation", 3), ("rotation", 4), ("scale", 3)) if k in node]
    except (TypeError, ValueError):
        g.fail(f"node {n}'s transform is not numbers of the right shape", "export the scene again")
    if not all(np.isfinite(v).all() for v in given):
        g.fail(f"node {n}'s transform has a number that is not finite", "fix the node's transform")
    if "matrix" in node:
        return given[0].reshape(4, 4).T   # glTF stores columns
    t = np.array(node.get("translation", [0, 0, 0]), dtype=float).reshape(3)
    x, y, z, w = np.array(node.get("rotation", [0, 0, 0, 1]), dtype=float).reshape(4)
    s = np.array(node.get("scale", [1, 1, 1]), dtype=float).reshape(3)
    m = np.eye(4)
    m[:3, :3] = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                          [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                          [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]) * s[None, :]
    m[:3, 3] = t
    return m


def _primitives(g: _Gltf, meshes: list, mesh) -> list[dict]:
    """A mesh's primitives, each checked to be triangles with positions."""
    if not isinstance(mesh, int) or not 0 <= mesh < len(meshes):
        g.fail(f"mesh {_brief(mesh)} does not exist", "export the scene again")
    prims = meshes[mesh].get("primitives", [])
    if not isinstance(prims, list) or not all(isinstance(p, dict) and isinstance(p.get("attributes"), dict)
                                              and "POSITION" in p["attributes"] for p in prims):
        g.fail(f"mesh {mesh}'s primitives lack positions", "export the scene again")
    for p in prims:
        if p.get("mode", 4) != 4:
            g.fail(f"mesh {mesh} has a primitive that is not triangles (mode {_brief(p.get('mode'))})",
                   "export the scene as triangles")
        if p.get("extensions"):
            g.fail(f"mesh {mesh} uses an extension ({', '.join(map(str, p['extensions']))[:100]})",
                   "export the scene without compression (no Draco, no meshopt)")
    return prims


def _triangles(g: _Gltf, prim: dict) -> int:
    """A primitive's triangles, from its accessor's count (nothing decoded)."""
    accessors = g.items("accessors", MAX_SCENE_NODES)
    k = prim.get("indices", prim["attributes"]["POSITION"])
    if not isinstance(k, int) or not 0 <= k < len(accessors) or _int(accessors[k].get("count")) < 0:
        g.fail(f"accessor {_brief(k)} does not exist or has no count", "export the scene again")
    return accessors[k]["count"] // 3


# ---------------------------------------------------------------- STEP


def _read_step(path: Path) -> list[PartShape]:
    """A STEP file's parts: meshed by Open CASCADE (cascadio, the ``step`` extra) into a GLB in metres, in a
    child process bounded in time and memory (a CAD kernel's failure or hang never takes the command
    with it), then read as a scene whose parts are the STEP products (a product used several times:
    ``name.1``, ``name.2``, ...)."""
    import importlib.util
    import subprocess
    import sys
    import tempfile

    _bytes(path, MAX_STEP_BYTES, "a STEP file")
    if importlib.util.find_spec("cascadio") is None:
        raise GeometryError(f"{_shown(path.name)}: reading STEP needs the step extra: pip install "
                            "'opportune[geometry,step]' (or convert the file to GLB: docs/derive.md)")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "step.glb"
        try:
            done = subprocess.run([sys.executable, "-c", _STEP_SCRIPT, str(path), str(out)], capture_output=True,
                                  timeout=STEP_SECONDS, preexec_fn=_step_bounds, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            raise GeometryError(f"{_shown(path.name)}: meshing the STEP file took over {STEP_SECONDS} s; simplify "
                                "it, or mesh it yourself and give a GLB") from None
        if done.returncode != 0 or not out.is_file():
            why = " ".join(done.stderr.decode("utf-8", "replace").split()[-30:])
            raise GeometryError(f"{_shown(path.name)}: Open CASCADE could not mesh the STEP file "
                                f"({_shown(why[-300:]) or 'exit ' + str(done.returncode)}); export it again")
        g = _Gltf(path, _bytes(out, MAX_SCENE_BYTES, "a STEP file's meshes", path))
    _name_by_product(g)
    return _read_gltf(path, 1.0, g)


#: The child process that meshes a STEP file: one thread, cascadio's default deflections.
_STEP_SCRIPT = ("import sys, cascadio\n"
                "sys.exit(0 if cascadio.step_to_glb(sys.argv[1], sys.argv[2], use_parallel=False) == 0 else 1)\n")


def _step_bounds() -> None:   # pragma: no cover (runs in the child, before it starts)
    """The child's memory: at most :data:`STEP_MEMORY` bytes of address space."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (STEP_MEMORY, STEP_MEMORY))


def _name_by_product(g: _Gltf) -> None:
    """Name each mesh node of a converted STEP file by its product (its mesh's name): cascadio numbers the
    nodes and names the meshes."""
    nodes, meshes = g.items("nodes", MAX_SCENE_NODES), g.items("meshes", MAX_SCENE_NODES)
    names = [m.get("name") if isinstance(m.get("name"), str) and m.get("name") else f"part{k}"
             for k, m in enumerate(meshes)]
    uses: dict[int, int] = {}
    for node in nodes:
        if isinstance(node.get("mesh"), int) and 0 <= node["mesh"] < len(meshes):
            uses[node["mesh"]] = uses.get(node["mesh"], 0) + 1
    seen: dict[int, int] = {}
    for node in nodes:
        m = node.get("mesh")
        if m in uses:
            seen[m] = seen.get(m, 0) + 1
            node["name"] = names[m] + (f".{seen[m]}" if uses[m] > 1 else "")
        elif "name" in node:
            del node["name"]     # assemblies are groups: a part is a product


# ---------------------------------------------------------------- MJCF


def _read_mjcf(path: Path, scale: float) -> list[PartShape]:
    """The parts of an MJCF model: checked with expat, compiled by MuJoCo, geoms meshed in world pose."""
    _scan_mjcf(path)
    try:
        import mujoco
    except ImportError:
        raise GeometryError(f"{_shown(path.name)}: reading an MJCF model needs MuJoCo: pip install "
                            "'opportune[geometry,physics]'") from None
    try:
        spec = mujoco.MjSpec.from_file(str(path))
        for t in spec.textures:    # only geometry is wanted: a texture's pixels (a file, or a huge builtin) never
            t.file, t.content_type, t.cubefiles = "", "", [""] * 6
            t.builtin, t.type, t.width, t.height = mujoco.mjtBuiltin.mjBUILTIN_FLAT, mujoco.mjtTexture.mjTEXTURE_2D, 1, 1
        model = spec.compile()
    except Exception as exc:   # MuJoCo reports every problem of a model as one kind of error, with its line
        raise GeometryError(f"{_shown(path.name)}: MuJoCo refuses the model: "
                            f"{_shown(' '.join(str(exc).split())[:300])}; fix the model") from None
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    owner = _body_owners(model, _shown(path.name))
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for k in range(model.ngeom):
        kind = int(model.geom_type[k])
        if kind == mujoco.mjtGeom.mjGEOM_PLANE or not (model.geom_contype[k] or model.geom_conaffinity[k]):
            continue   # an infinite floor is no part; a geom that collides with nothing is only drawn
        body = int(model.geom_bodyid[k])
        part = owner[body]
        if part is None:
            raise GeometryError(f"{_shown(path.name)}: geom {_geom_label(model, k)} is in the worldbody or an "
                                "unnamed body under it; put it in a named body (a part)")
        local, faces = _geom_mesh(mujoco, model, k, part, path)
        world = local @ data.geom_xmat[k].reshape(3, 3).T + data.geom_xpos[k]
        pieces.setdefault(part, []).append((world, faces))
    parts = []
    for part, items in pieces.items():
        triangles = sum(len(f) for _, f in items)
        if triangles > MAX_TRIANGLES:
            raise GeometryError(f"{_shown(path.name)}: body {part!r} has {triangles:,} triangles; a part has at "
                                f"most {MAX_TRIANGLES:,}: simplify its meshes")
        bodies = [b for v, f in items for b in mesh_bodies(part, v, f, scale=scale, join=True)]
        parts.append(PartShape(part, path, tuple(bodies), triangles))
    return parts


def _body_owners(model, file: str) -> list[str | None]:
    """For each body, its part: its name, or its nearest named ancestor's; None in the worldbody."""
    owner: list[str | None] = [None]
    for b in range(1, model.nbody):
        name = model.body(b).name
        if name and _bad_id(name):
            raise GeometryError(f"{file}: body {b}'s name {_bad_id(name)}; rename the body")
        owner.append(name if name else owner[int(model.body_parentid[b])])
    return owner


def _geom_label(model, k: int) -> str:
    name = model.geom(k).name
    return repr(name) if name else str(k)


def _geom_mesh(mujoco, model, k: int, part: str, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A geom's surface in its own frame: a mesh's vertices and faces, or a primitive meshed."""
    import trimesh.creation as make

    kind, size = int(model.geom_type[k]), np.array(model.geom_size[k], dtype=float)
    g = mujoco.mjtGeom
    if kind == g.mjGEOM_MESH:
        m = int(model.geom_dataid[k])
        va, vn = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        fa, fn = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        return np.array(model.mesh_vert[va:va + vn], dtype=float), np.array(model.mesh_face[fa:fa + fn], dtype=np.int64)
    if kind == g.mjGEOM_BOX:
        mesh = make.box(extents=2 * size)
    elif kind == g.mjGEOM_CYLINDER:
        mesh = make.cylinder(radius=size[0], height=2 * size[1], sections=CYLINDER_SECTIONS)
    elif kind == g.mjGEOM_CAPSULE:
        mesh = make.capsule(height=2 * size[1], radius=size[0], count=[CYLINDER_SECTIONS // 2] * 2)
    elif kind in (g.mjGEOM_SPHERE, g.mjGEOM_ELLIPSOID):
        mesh = make.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=1.0)
        mesh.apply_scale(size if kind == g.mjGEOM_ELLIPSOID else size[0])
    else:
        raise GeometryError(f"{_shown(path.name)}: body {part!r}: geom {_geom_label(model, k)} is of a type not "
                            "read (height field or SDF); give it as a mesh")
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def _scan_mjcf(path: Path) -> None:
    """Check an MJCF file and its includes before MuJoCo reads them: each file's bytes, no DTD or entity,
    the elements, their depth, the includes' depth, the bodies and geoms, no element that multiplies
    bodies, and every mesh file a regular file within :data:`~opportune.limits.MAX_MESH_BYTES`."""
    counts = {"element": 0, "body": 0, "geom": 0}
    meshdirs: list[str] = []
    meshes: list[str] = []
    _scan_xml(path, path.parent, 0, counts, meshdirs, meshes)
    for name in meshes:
        base = path.parent / (meshdirs[-1] if meshdirs else "")
        _bytes(base / name, MAX_MESH_BYTES, "a part's mesh file", path)


def _scan_xml(path: Path, home: Path, depth: int, counts: dict, meshdirs: list, meshes: list,
              source: Path | None = None) -> None:
    """One XML file of the model (``depth`` includes down), scanned with expat."""
    name = _shown(path.name)
    raw = _bytes(path, MAX_XML_BYTES, "an MJCF file", source)
    counts["bytes"] = counts.get("bytes", 0) + len(raw)
    if counts["bytes"] > MAX_XML_BYTES:
        raise GeometryError(f"{name}: the model and its includes have more than {MAX_XML_BYTES:,} bytes in all; "
                            "split the assembly")
    parser = expat.ParserCreate()
    open_tags: list[str] = []
    includes: list[str] = []

    def refuse(*_args):
        raise GeometryError(f"{name}: line {parser.CurrentLineNumber}: the file declares a DTD or entities; remove "
                            "the <!DOCTYPE ...> and <!ENTITY ...> declarations: MJCF needs none")

    def start(tag, attrs):
        counts["element"] += 1
        if counts["element"] > MAX_XML_ELEMENTS or len(open_tags) >= MAX_SCENE_DEPTH:
            raise GeometryError(f"{name}: line {parser.CurrentLineNumber}: more than {MAX_XML_ELEMENTS:,} elements "
                                f"or nested more than {MAX_SCENE_DEPTH} deep; split the assembly")
        if tag in _MJCF_REFUSED:
            raise GeometryError(f"{name}: line {parser.CurrentLineNumber}: <{_shown(tag)}> is not read (it multiplies "
                                "bodies or loads data no part's shape needs); expand or remove it")
        if tag in ("body", "geom"):
            counts[tag] += 1
            most = MAX_MJCF_BODIES if tag == "body" else MAX_GEOMS
            if counts[tag] > most:
                raise GeometryError(f"{name}: more than {most:,} <{tag}> elements; an MJCF assembly has at most "
                                    f"{most:,}: derive subassemblies separately")
        if tag == "include":
            includes.append(attrs.get("file", ""))
        elif tag == "mesh" and "file" in attrs:
            meshes.append(attrs["file"])
        elif tag == "compiler" and ("meshdir" in attrs or "assetdir" in attrs):
            meshdirs.append(attrs.get("meshdir", attrs.get("assetdir")))
        open_tags.append(tag)

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: open_tags.pop()
    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    try:
        parser.Parse(raw, True)
    except expat.ExpatError as exc:
        raise GeometryError(f"{name}: not XML ({_shown(str(exc))}); fix the file") from None
    for file in includes:
        if depth + 1 > MAX_INCLUDE_DEPTH:
            raise GeometryError(f"{name}: includes nested more than {MAX_INCLUDE_DEPTH} deep (or an include of "
                                "itself); flatten the includes")
        _scan_xml(home / file, home, depth + 1, counts, meshdirs, meshes, path)
