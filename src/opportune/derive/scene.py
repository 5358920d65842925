"""An assembly read from one scene file: a glTF/GLB scene or a STEP file (MJCF: :mod:`opportune.derive.mjcf`).

* **glTF / GLB**: each named node that carries a mesh is a part (its id the node's name); nodes without
  a name join their nearest named ancestor (a part drawn as several meshes); world transforms are
  applied.  The file is read by this module, not handed to a loader whole: its JSON is checked first
  (nodes, depth, buffers' bytes, each part's triangles, all against :mod:`opportune.limits`), then only
  the positions and indices of the parts' triangles are decoded.  Materials and images are never read.
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

import numpy as np

from opportune.derive.geometry import UNITS, Assembly, GeometryError, PartShape, assembly_of, check_units, mesh_bodies
from opportune.limits import (MAX_ID, MAX_MESH_PARTS, MAX_SCENE_BYTES, MAX_SCENE_DEPTH, MAX_SCENE_NODES, MAX_STEP_BYTES,
                              MAX_TRIANGLES, STEP_MEMORY, STEP_SECONDS)

#: glTF accessor component types read: for positions ``float32``; for indices unsigned integers.
_COMPONENTS = {5126: np.dtype("<f4"), 5121: np.dtype("u1"), 5123: np.dtype("<u2"), 5125: np.dtype("<u4")}



def read_scene_assembly(path: str | Path, *, units: str = "m", tolerance: float | None = None) -> Assembly:
    """Read a glTF/GLB scene or a STEP file in the assembled pose.

    Parameters
    ----------
    path : str or Path
        A ``.glb``, ``.gltf``, ``.step`` or ``.stp`` file.
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
    >>> read_scene_assembly("missing.glb", units="inch")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: units 'inch': give one of m, mm
    """
    check_units(units, tolerance)
    return assembly_of(read_scene(Path(path), UNITS[units]), units, tolerance)


def read_scene(path: Path, scale: float) -> tuple[PartShape, ...]:
    """The parts of a glTF/GLB scene or a STEP file, sorted by id, in metres.

    Parameters
    ----------
    path : Path
        A ``.glb``, ``.gltf``, ``.step`` or ``.stp`` file.
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
    opportune.derive.geometry.GeometryError: missing.glb: not a file; give a glTF/GLB scene or a STEP file
    """
    if not path.is_file():
        raise GeometryError(f"{shown(path.name)}: not a file; give a glTF/GLB scene or a STEP file")
    if path.suffix.lower() in (".glb", ".gltf"):
        try:
            parts = _read_gltf(path, scale)
        except GeometryError:
            raise
        except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
            # the JSON is the file's: a value of a kind no check above foresaw is the same refusal
            raise GeometryError(f"{shown(path.name)}: not a glTF scene this reader follows ({type(exc).__name__}: "
                                f"{shown(str(exc)[:120])}); export the scene again") from None
    else:
        parts = _read_step(path)
    if not parts:
        raise GeometryError(f"{shown(path.name)}: no part (no named node with a mesh); name "
                            "each part's node")
    return tuple(sorted(parts, key=lambda p: p.id))


def id_problem(name: str) -> str:
    """What is wrong with a node's or body's name as a part id: too long or holding a control character
    (a part id reaches terminals and plan files).

    Parameters
    ----------
    name : str
        The name.

    Returns
    -------
    str
        The problem, to follow the name in a message; ``""`` when there is none.

    Examples
    --------
    >>> id_problem("bolt")
    ''
    >>> print(id_problem("b" + chr(27)))
    'b\\x1b' holds a control character; a part id is printable text
    """
    if len(name) > MAX_ID:
        return f"has {len(name):,} characters; a part id has at most {MAX_ID}"
    if not name.isprintable():
        return f"{name!r} holds a control character; a part id is printable text"
    return ""


def _brief(value) -> str:
    """A value of the file for a message: its repr, cut short (a file may put a megabyte where a number goes)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def shown(text: str) -> str:
    """User text for a message: control characters escaped (never sent raw to a terminal).

    Parameters
    ----------
    text : str
        A name or path from the user's files.

    Returns
    -------
    str
        The text, or its escaped form if it holds a character that is not printable.

    Examples
    --------
    >>> print(shown("a.glb"), shown("a" + chr(27) + ".glb"))
    a.glb a\\x1b.glb
    """
    return text if text.isprintable() else repr(text)[1:-1]


def file_bytes(path: Path, most: int, what: str, source: Path | None = None) -> bytes:
    """A regular file's bytes, its size checked before it is read.

    Parameters
    ----------
    path : Path
        The file.
    most : int
        The most bytes it may have.
    what : str
        What the file is, for the message ("a scene file").
    source : Path, optional
        The file that names it (a scene's buffer, a model's mesh), named first in the message.

    Returns
    -------
    bytes
        Its content.

    Raises
    ------
    GeometryError
        Not a regular file (a folder, a device, missing), or over ``most`` bytes.

    Examples
    --------
    >>> file_bytes(Path("/dev/zero"), 10, "a mesh")
    Traceback (most recent call last):
    ...
    opportune.derive.geometry.GeometryError: /dev/zero is not a regular file; give a mesh as a file
    """
    head = f"{shown(source.name)}: " if source is not None else ""
    if not path.is_file():
        raise GeometryError(f"{head}{shown(str(path))} is not a regular file; give {what} as a file")
    size = path.stat().st_size
    if size > most:
        raise GeometryError(f"{head}{shown(path.name)}: {size:,} bytes; {what} has at most {most:,} bytes: split "
                            "the assembly or simplify its meshes")
    return path.read_bytes()


# ---------------------------------------------------------------- glTF and GLB


class _Gltf:
    """A glTF document being read: its JSON, the binary chunk of a GLB, the buffers decoded so far."""

    def __init__(self, path: Path, raw: bytes | None = None):
        self.path, self.name = path, shown(path.name)
        raw = file_bytes(path, MAX_SCENE_BYTES, "a scene file") if raw is None else raw
        self.bin = b""
        if raw[:4] == b"glTF":
            raw = self._glb(raw)
        try:
            self.doc = json.loads(raw)
        except (ValueError, RecursionError) as exc:
            self.fail(f"not glTF JSON ({type(exc).__name__}: {shown(str(exc)[:120])})", "export the scene again")
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
            data = file_bytes(self.path.parent / uri, MAX_SCENE_BYTES - self.read, "a scene's buffers in all", self.path)
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
    bad = id_problem(owner)
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

    file_bytes(path, MAX_STEP_BYTES, "a STEP file")
    if importlib.util.find_spec("cascadio") is None:
        raise GeometryError(f"{shown(path.name)}: reading STEP needs the step extra: pip install "
                            "'opportune[geometry,step]' (or convert the file to GLB: docs/derive.md)")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "step.glb"
        try:
            done = subprocess.run([sys.executable, "-c", _STEP_SCRIPT, str(path), str(out)], capture_output=True,
                                  timeout=STEP_SECONDS, preexec_fn=_step_bounds, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            raise GeometryError(f"{shown(path.name)}: meshing the STEP file took over {STEP_SECONDS} s; simplify "
                                "it, or mesh it yourself and give a GLB") from None
        if done.returncode != 0 or not out.is_file():
            why = " ".join(done.stderr.decode("utf-8", "replace").split()[-30:])
            raise GeometryError(f"{shown(path.name)}: Open CASCADE could not mesh the STEP file "
                                f"({shown(why[-300:]) or 'exit ' + str(done.returncode)}); export it again")
        g = _Gltf(path, file_bytes(out, MAX_SCENE_BYTES, "a STEP file's meshes", path))
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
