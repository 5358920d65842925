"""What `opportune derive` reads: glTF/GLB scenes, MuJoCo MJCF models and the assembly's manifest.

One voxel assembly written three ways (a folder of OBJ files, a GLB scene of named nodes with transformed
unnamed children, an MJCF model of box geoms) derives one plan, and its count is the brute force's of
tests/test_derive.py.  The GLB reader (this project's own) is checked against trimesh's on transformed
nodes.  Quantities are checked exhaustively against the brute force over distinct instances, projected
to part ids; process constraints against the brute force filtered by them.  Every new door is given
hostile input: exit 1, a message naming the file and what to do, no traceback.
"""

from __future__ import annotations

import base64
import itertools
import json
import struct
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("trimesh", reason="the geometry extra, which make test installs")

from conftest import run_cli  # noqa: E402
from opportune.derive import DeriveError, GeometryError, ManifestError, derive  # noqa: E402
from opportune.engine import Schedule  # noqa: E402
from test_derive import AXES, BruteForce, admits, closure, cube_lines, partition, write_assembly  # noqa: E402

# one unit cube centred on the origin: vertices and outward triangles (0-based), from the OBJ writer's
_LINES = cube_lines([(0, 0, 0)])
CUBE_V = np.array([[float(x) - 0.5 for x in ln.split()[1:]] for ln in _LINES if ln.startswith("v ")])
CUBE_F = np.array([[int(x) - 1 for x in ln.split()[1:]] for ln in _LINES if ln.startswith("f ")])


# ---------------------------------------------------------------- writers: GLB and MJCF


def glb_bytes(doc: dict, binary: bytes) -> bytes:
    """A GLB file: the JSON chunk and the binary chunk, each padded to 4 bytes."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\0") + binary)


def cube_doc(nodes: list[dict], roots: list[int]) -> tuple[dict, bytes]:
    """A glTF document whose mesh 0 is the unit cube centred on the origin (positions, then indices)."""
    pos, idx = CUBE_V.astype("<f4").tobytes(), CUBE_F.astype("<u2").tobytes()
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": roots}], "nodes": nodes,
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3"},
                         {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                           {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)}],
           "buffers": [{"byteLength": len(pos) + len(idx)}]}
    return doc, pos + idx


def write_glb(path: Path, parts: dict[str, list[tuple[int, int, int]]]) -> Path:
    """The parts as a GLB scene: a named root scaled by 2, each part a named node scaled by 1/2, each cell
    an unnamed child turned 90° about z and moved to the cell's centre (one cube mesh, instanced)."""
    nodes = [{"name": "product", "scale": [2, 2, 2], "children": []}]
    quarter = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    for name, cells in parts.items():
        part = {"name": name, "scale": [0.5, 0.5, 0.5], "children": []}
        nodes[0]["children"].append(len(nodes))
        nodes.append(part)
        for c in cells:
            part["children"].append(len(nodes))
            nodes.append({"mesh": 0, "translation": [x + 0.5 for x in c], "rotation": quarter})
    path.write_bytes(glb_bytes(*cube_doc(nodes, [0])))
    return path


def write_mjcf(path: Path, parts: dict[str, list[tuple[int, int, int]]], extra: str = "") -> Path:
    """The parts as an MJCF model: each a body (moved by one unit, its geoms moved back) of box geoms, a
    floor plane and a drawn-only sphere that the reader leaves out."""
    body = []
    for name, cells in parts.items():
        geoms = "".join(f'<geom type="box" size=".5 .5 .5" pos="{x - 0.5} {y - 0.5} {z - 0.5}"/>' for x, y, z in cells)
        body.append(f'<body name="{name}" pos="1 1 1">{geoms}<geom type="sphere" size="9" contype="0" '
                    f'conaffinity="0"/></body>')
    path.write_text(f'<mujoco model="voxels">{extra}<worldbody><geom type="plane" size="9 9 .1" pos="0 0 -3"/>'
                    + "".join(body) + "</worldbody></mujoco>")
    return path


def requires_of(derived) -> set:
    doc = derived.plan.to_dict()
    strategies = doc.get("strategies") or [{"requires": doc.get("requires", {})}]
    return {frozenset((b, a) for a, bs in s["requires"].items() for b in bs) for s in strategies}


def fail_text(*args) -> str:
    r = run_cli("derive", *args)
    assert r.exit_code == 1, r.output
    assert "error:" in r.output
    return " ".join(r.output.split())


# ---------------------------------------------------------------- one assembly, three formats


#: A box: a base, two walls around a peg, a lid (4 strategies, 96 of the 120 orders).
BOX = {"base": [(x, y, 0) for x in range(3) for y in range(3)], "peg": [(1, 1, 1)],
       "left": [(0, y, 1) for y in range(3)] + [(1, 0, 1)], "right": [(2, y, 1) for y in range(3)] + [(1, 2, 1)],
       "lid": [(x, y, 2) for x in range(3) for y in range(3)]}
THREE_WAYS = {"box": (BOX, (3, 3, 3), 4), "block of 8": (partition((3, 3, 3), 8, 0), (3, 3, 3), 4),
              "block of 6": (partition((2, 3, 2), 6, 9), (2, 3, 2), 1)}


@pytest.mark.parametrize("case", sorted(THREE_WAYS))
def test_one_assembly_as_obj_glb_and_mjcf_derives_one_plan(tmp_path, case):
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    parts, block, strategies = THREE_WAYS[case]
    brute = BruteForce(parts, block)
    got = []
    for where in (write_assembly(tmp_path / "obj", parts), write_glb(tmp_path / "a.glb", parts),
                  write_mjcf(tmp_path / "a.xml", parts)):
        got.append(derive(where))
    assert got[0].blocking.blockers == got[1].blocking.blockers == got[2].blocking.blockers
    assert requires_of(got[0]) == requires_of(got[1]) == requires_of(got[2])
    assert len(requires_of(got[0])) == strategies
    assert Schedule(got[1].plan).count() == Schedule(got[2].plan).count() == brute.count() > 0


def test_the_glb_reader_agrees_with_trimesh_on_turned_and_scaled_nodes(tmp_path):
    """Named nodes with rotations, scales and translations, exported by trimesh: each part's vertices as
    this project's reader places them are trimesh's own scene graph's, transformed."""
    import trimesh
    from trimesh import transformations as tf

    from opportune.derive.scene import read_scene

    scene = trimesh.Scene()
    rng = np.random.default_rng(5)
    for i in range(4):
        turn = tf.rotation_matrix(rng.uniform(0, np.pi), rng.normal(size=3))
        move = tf.translation_matrix([3.0 * i, rng.uniform(-1, 1), 0])
        scene.add_geometry(trimesh.creation.box(extents=rng.uniform(0.5, 1.5, size=3)), node_name=f"part{i}",
                           transform=move @ turn @ np.diag([1.0, 1.0, 2.0, 1.0]))
    path = tmp_path / "turned.glb"
    path.write_bytes(scene.export(file_type="glb"))
    ours = {p.id: p for p in read_scene(path, 1.0)}
    theirs = trimesh.load(str(path), process=False)
    assert sorted(ours) == sorted(theirs.graph.nodes_geometry)
    for node in theirs.graph.nodes_geometry:
        matrix, geometry = theirs.graph[node]
        expected = trimesh.transform_points(theirs.geometry[geometry].vertices, matrix)
        got = np.vstack([b.vertices for b in ours[node].bodies])
        assert np.allclose(np.sort(got, axis=0), np.sort(np.unique(expected.round(9), axis=0), axis=0), atol=1e-6)


def test_a_gltf_with_its_buffer_beside_it_is_read_and_one_elsewhere_is_refused(tmp_path):
    parts = {"a": [(0, 0, 0)], "b": [(1, 0, 0)]}
    doc, binary = cube_doc([{"name": "a", "mesh": 0}, {"name": "b", "mesh": 0, "translation": [1, 0, 0]}], [0, 1])
    (tmp_path / "cube.bin").write_bytes(binary)
    doc["buffers"][0]["uri"] = "cube.bin"
    (tmp_path / "two.gltf").write_text(json.dumps(doc))
    assert Schedule(derive(tmp_path / "two.gltf").plan).count() == BruteForce(parts, (2, 1, 1)).count() == 2
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    (tmp_path / "inline.gltf").write_text(json.dumps(doc))
    assert Schedule(derive(tmp_path / "inline.gltf").plan).count() == 2
    for uri in ("../cube.bin", "/etc/passwd", "sub/cube.bin", "file:cube.bin"):
        doc["buffers"][0]["uri"] = uri
        (tmp_path / "away.gltf").write_text(json.dumps(doc))
        assert "not a file beside the scene" in fail_text(tmp_path / "away.gltf")


def test_mjcf_primitives_and_meshes_in_world_pose(tmp_path):
    """A cylinder peg in a ring of boxes goes in along ±z only; a sphere and a capsule resting on the ring
    are meshed; a mesh geom (an OBJ cube, in a turned body) reads as the box it is."""
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    (tmp_path / "cube.obj").write_text("\n".join(cube_lines([(0, 0, 0)])) + "\n")
    ring = "".join(f'<geom type="box" size=".5 .5 .5" pos="{x} {y} 0"/>'
                   for x in (-1, 0, 1) for y in (-1, 0, 1) if (x, y) != (0, 0))
    (tmp_path / "peg.xml").write_text(
        '<mujoco><asset><mesh name="cube" file="cube.obj"/></asset><worldbody>'
        f'<body name="ring">{ring}</body>'
        '<body name="peg"><geom type="cylinder" size=".5 .5"/></body>'
        '<body name="ball" pos="0 0 1"><geom type="sphere" size=".5"/></body>'
        '<body name="pill" pos="3 0 0"><geom type="capsule" size=".3 .2"/></body>'
        '<body name="block" pos="0 3 .5" euler="0 0 90"><geom type="mesh" mesh="cube"/></body>'
        '</worldbody></mujoco>')
    derived = derive(tmp_path / "peg.xml")
    peg = derived.blocking.blockers["peg"]
    assert {d for d, q in peg.items() if not q} == {"+z"}      # from below; from above the ball is in the way
    assert peg["-z"] == {"ball"} and all("ring" in q for d, q in peg.items() if "z" not in d)
    from opportune.derive.mjcf import read_mjcf_assembly

    shapes = {p.id: p for p in read_mjcf_assembly(tmp_path / "peg.xml").parts}
    # the OBJ's cube [0, 1]^3 in the body's frame, turned a quarter about z and moved to (0, 3, 0.5)
    assert np.allclose(shapes["block"].bounds, [[-1.0, 3.0, 0.5], [0.0, 4.0, 1.5]], atol=1e-9)
    assert np.allclose(shapes["peg"].bounds[:, 2], [-0.5, 0.5]) and shapes["peg"].bounds[1, 0] <= 0.5
    assert np.allclose(shapes["pill"].bounds[:, 2], [-0.5, 0.5])


# ---------------------------------------------------------------- hostile scenes


def glb_case(tmp_path: Path, case: str) -> Path:
    """A GLB file broken one way."""
    nodes = [{"name": "a", "mesh": 0}, {"name": "b", "mesh": 0, "translation": [1, 0, 0]}]
    doc, binary = cube_doc(nodes, [0, 1])
    if case == "deep":
        doc["nodes"] = [{"name": "a", "children": [1]}] + [{"children": [i + 1]} for i in range(1, 80)] + [{"mesh": 0}]
    elif case == "cycle":
        doc["nodes"][0]["children"] = [0]
    elif case == "unnamed":
        del doc["nodes"][1]["name"]
    elif case == "twice":
        doc["nodes"][1]["name"] = "a"
    elif case == "nan":
        doc["nodes"][1]["translation"] = [float("nan"), 0, 0]
    elif case == "huge count":
        doc["accessors"][0]["count"] = 70_000
    elif case == "past the buffer":
        doc["accessors"][1]["byteOffset"] = 64
    elif case == "draco":
        doc["meshes"][0]["primitives"][0]["extensions"] = {"KHR_draco_mesh_compression": {}}
    elif case == "lines":
        doc["meshes"][0]["primitives"][0]["mode"] = 1
    elif case == "control":
        doc["nodes"][1]["name"] = "b\x1b[31m"
    elif case == "many nodes":
        doc["nodes"] += [{"name": f"n{i}"} for i in range(10_001)]
    path = tmp_path / "bad.glb"
    if case == "not json":
        path.write_bytes(glb_bytes(doc, binary).replace(b'"asset"', b'"asset"}}}', 1))
    elif case == "cut short":
        path.write_bytes(glb_bytes(doc, binary)[:18])
    elif case == "deep json":
        path.write_bytes(b"[" * 200_000 + b"]" * 200_000)
    else:
        path.write_bytes(glb_bytes(doc, binary))
    return path


GLB_CASES = {"deep": "nested more than 64 levels", "cycle": "two parents", "unnamed": "has a name",
             "twice": "two nodes (0 and 1) are named 'a'", "nan": "not finite", "huge count": "at most 60,000",
             "past the buffer": "reaches past", "draco": "without compression", "lines": "not triangles",
             "control": "'b\\x1b[31m' holds a control character", "many nodes": "at most 10,000", "not json": "not glTF JSON",
             "cut short": "cut short", "deep json": "not glTF JSON"}


@pytest.mark.parametrize("case", sorted(GLB_CASES))
def test_a_hostile_glb_is_refused_naming_the_file(tmp_path, case):
    text = fail_text(glb_case(tmp_path, case))
    assert "bad.glb" in text and GLB_CASES[case] in text, text
    assert "\x1b" not in text


def test_the_scene_limits_are_checked_before_the_work(tmp_path, monkeypatch):
    from opportune.derive import scene

    path = write_glb(tmp_path / "two.glb", {"a": [(0, 0, 0), (1, 0, 0)], "b": [(0, 1, 0)]})
    monkeypatch.setattr(scene, "MAX_TRIANGLES", 23)
    assert "part 'a' has 24 triangles" in fail_text(path)
    monkeypatch.setattr(scene, "MAX_TRIANGLES", 20_000)
    monkeypatch.setattr(scene, "MAX_SCENE_BYTES", 100)
    assert "at most 100 bytes" in fail_text(path)
    monkeypatch.setattr(scene, "MAX_SCENE_BYTES", 1 << 20)
    monkeypatch.setattr(scene, "MAX_MESH_PARTS", 1)
    assert "more than 1 parts" in fail_text(path)


MJCF_CASES = {
    "entities": ('<?xml version="1.0"?><!DOCTYPE m [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;">]>'
                 '<mujoco><worldbody><body name="&b;"><geom type="box" size="1 1 1"/></body></worldbody></mujoco>',
                 "DTD or entities"),
    "self include": ('<mujoco><include file="bad.xml"/></mujoco>', "includes nested more than 8"),
    "replicate": ('<mujoco><worldbody><replicate count="100000" offset="1 0 0"><body name="a"><geom type="box" '
                  'size="1 1 1"/></body></replicate></worldbody></mujoco>', "<replicate> is not read"),
    "deep": ("<mujoco><worldbody>" + "<body>" * 70 + '<geom type="box" size="1 1 1"/>' + "</body>" * 70
             + "</worldbody></mujoco>", "nested more than 64 deep"),
    "world geom": ('<mujoco><worldbody><geom type="box" size="1 1 1"/></worldbody></mujoco>', "named body"),
    "zero mesh": ('<mujoco><asset><mesh name="z" file="/dev/zero"/></asset><worldbody><body name="a"><geom '
                  'type="mesh" mesh="z"/></body></worldbody></mujoco>', "not a regular file"),
    "mujoco refuses": ('<mujoco><worldbody><body name="a"><geom type="box" size="1 1 1" bogus="2"/></body>'
                       '</worldbody></mujoco>', "MuJoCo refuses the model"),
    "not xml": ("<mujoco><worldbody>", "not XML"),
    "control": ('<mujoco><worldbody><body name="a&#155;[31m"><geom type="box" size="1 1 1"/></body><body name="b">'
                '<geom type="box" size="1 1 1" pos="0.5 0 0"/></body></worldbody></mujoco>', "holds a control character"),
}


@pytest.mark.parametrize("case", sorted(MJCF_CASES))
def test_a_hostile_mjcf_is_refused_naming_the_file(tmp_path, case):
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    xml, expected = MJCF_CASES[case]
    (tmp_path / "bad.xml").write_text(xml)
    text = fail_text(tmp_path / "bad.xml")
    assert expected in text and "\x1b" not in text, text
    assert "bad.xml" in text


def test_the_mjcf_limits_are_checked_before_mujoco_reads_the_model(tmp_path, monkeypatch):
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    from opportune.derive import mjcf

    path = write_mjcf(tmp_path / "m.xml", {"a": [(0, 0, 0), (1, 0, 0)], "b": [(0, 1, 0)]})
    for name, value, expected in [("MAX_MJCF_BODIES", 1, "more than 1 <body>"), ("MAX_GEOMS", 3, "more than 3 <geom>"),
                                  ("MAX_XML_BYTES", 100, "at most 100 bytes"),
                                  ("MAX_XML_ELEMENTS", 5, "more than 5 elements")]:
        with monkeypatch.context() as m:
            m.setattr(mjcf, name, value)
            assert expected in fail_text(path), name


def test_an_mjcf_texture_of_any_size_is_never_built(tmp_path):
    """A builtin texture of 10^10 pixels (40 GB) and a texture file that does not exist: only geometry is
    compiled, so the model reads at once."""
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    path = write_mjcf(tmp_path / "t.xml", {"a": [(0, 0, 0)], "b": [(1, 0, 0)]},
                      '<asset><texture name="t" type="2d" builtin="checker" width="100000" height="100000"/>'
                      '<texture name="s" type="skybox" file="nowhere.png"/><material name="m" texture="t"/></asset>')
    assert Schedule(derive(path).plan).count() == 2


# ---------------------------------------------------------------- the manifest


BOLTS = {"plate": [(0, 0, 0), (1, 0, 0), (2, 0, 0)], "b1": [(0, 0, 1)], "spacer": [(1, 0, 1)], "b2": [(2, 0, 1)],
         "cover": [(0, 0, 2), (1, 0, 2), (2, 0, 2)]}


def projected(brute: BruteForce, groups: dict[str, list[str]]) -> set[tuple[str, ...]]:
    """The feasible sequences of part ids: each feasible sequence of instances with an instance replaced by
    its part's id (every permutation examined: the assemblies here have at most 6 instances)."""
    part_of = {i: p for p, g in groups.items() for i in g}
    return {tuple(part_of.get(i, i) for i in seq) for seq in itertools.permutations(brute.ids) if brute.feasible(seq)}


@pytest.mark.parametrize("directions", [None, ["+z", "-z"]])
def test_identical_parts_are_one_part_of_quantity_n_and_the_count_is_the_brute_forces(tmp_path, directions):
    """Two bolts between a plate and a cover: with the axes every part has a free way (no order); along
    ±z only each bolt goes in after the plate or before the cover."""
    folder = write_assembly(tmp_path / "bolts", BOLTS)
    brute = BruteForce(BOLTS, (3, 1, 3))
    if directions:
        brute.swept = [m[4:] for m in brute.swept]
    distinct = derive(folder, directions=directions)
    assert Schedule(distinct.plan).count() == brute.count()
    (folder / "assembly.yaml").write_text("quantities:\n  bolt: [b1, b2]\nnames: {bolt: hex bolt M6, plate: base plate}\n")
    merged = derive(folder, directions=directions)
    parts = {p.id: p for p in merged.plan.parts}
    assert parts["bolt"].quantity == 2 and parts["bolt"].name == "hex bolt M6" and "b1" not in parts
    # two interchangeable instances: each sequence of part ids is 2! sequences of instances
    assert Schedule(merged.plan).count() * 2 == brute.count() > 0
    feasible = projected(brute, {"bolt": ["b1", "b2"]})
    everything = set(itertools.permutations(["plate", "bolt", "spacer", "bolt", "cover"]))
    assert {s for s in everything if admits(merged.plan, s)} == feasible
    assert (len(feasible) < len(everything)) == bool(directions)
    r = run_cli("derive", folder, "-o", tmp_path / "plan.yaml")
    assert r.exit_code == 0 and "quantity: 2" in (tmp_path / "plan.yaml").read_text()


@pytest.mark.parametrize("directions", [None, ["+z", "-z"]])
def test_identical_parts_in_a_plan_written_as_ways_count_and_run_as_in_its_strategies(tmp_path, directions):
    """The two bolts of a quantity written as ways: the bolt is one part of quantity 2 whose units keep each
    instance's ways; the count is the strategies' (each sequence of part ids once), the plan admits exactly
    the projections of the brute force's feasible sequences, and the sequencer and `replay` take a look
    that names the bolt, either unit."""
    folder = write_assembly(tmp_path / "bolts", BOLTS)
    brute = BruteForce(BOLTS, (3, 1, 3))
    if directions:
        brute.swept = [m[4:] for m in brute.swept]
    strategies = derive(folder, directions=directions, quantities={"bolt": ["b1", "b2"]})
    ways = derive(folder, directions=directions, quantities={"bolt": ["b1", "b2"]}, form="ways")
    assert ways.plan.is_ways and {p.id: p.quantity for p in ways.plan.parts}["bolt"] == 2
    assert {"bolt#1", "bolt#2"} <= set(ways.plan.ways) and "b1" not in ways.plan.ways
    assert Schedule(ways.plan).count() == Schedule(strategies.plan).count() == brute.count() // 2 > 0
    feasible = projected(brute, {"bolt": ["b1", "b2"]})
    everything = set(itertools.permutations(["plate", "bolt", "spacer", "bolt", "cover"]))
    assert {s for s in everything if admits(ways.plan, s)} == feasible
    plan = tmp_path / "plan.yaml"
    import yaml

    plan.write_text(yaml.safe_dump(ways.plan.to_dict()), encoding="utf-8")     # read back through the checker
    assert str(Schedule(ways.plan).count()) in run_cli("count", plan).output
    for k, sequence in enumerate(sorted(feasible)[:3]):    # the camera shows one part at a time
        looks = tmp_path / f"seq{k}.looks"
        looks.write_text("\n".join(sequence) + "\n", encoding="utf-8")
        r = run_cli("replay", plan, looks, "--json")
        steps = json.loads(r.output)
        assert r.exit_code == 0 and steps[-1]["action"]["kind"] == "done" and steps[-1]["installed"] == list(sequence)


def test_a_part_between_two_instances_is_written_as_ways(tmp_path):
    """b1, x, b2 in a row along ±x: some sequences put x between the bolts, which a quantity of a plan of
    strategies cannot say; the plan written as ways can, and counts the brute force's sequences of part ids."""
    parts = {"b1": [(0, 0, 0)], "x": [(1, 0, 0)], "b2": [(2, 0, 0)]}
    folder = write_assembly(tmp_path / "row", parts)
    (folder / "assembly.yaml").write_text("directions: [+x, -x]\nquantities: {bolt: [b1, b2]}\n")
    brute = BruteForce(parts, (3, 1, 1))
    brute.swept = [m[:2] for m in brute.swept]
    with pytest.raises(ManifestError, match="'x' goes in between two instances of 'bolt'"):
        derive(folder, form="strategies")
    derived = derive(folder)
    assert derived.plan.is_ways and "written as each part's ways in instead" in derived.notes[0]
    feasible = projected(brute, {"bolt": ["b1", "b2"]})
    assert ("bolt", "x", "bolt") in feasible
    assert Schedule(derived.plan).count() == len(feasible) == brute.count() // 2
    assert {s for s in set(itertools.permutations(["bolt", "bolt", "x"])) if admits(derived.plan, s)} == feasible


def test_instances_the_geometry_tells_apart_are_refused(tmp_path):
    """Along ±z, a clip above b2 only: b2 has the clip in its way from above, b1 does not."""
    parts = dict(BOLTS, clip=[(2, 0, 3)])
    folder = write_assembly(tmp_path / "clip", parts)
    (folder / "assembly.yaml").write_text("directions: [+z, -z]\nquantities:\n  bolt: [b1, b2]\n")
    text = fail_text(folder)
    assert "assembly.yaml:3" in text and "'b1' and 'b2' are not interchangeable" in text and "separate parts" in text


@pytest.mark.parametrize("seed", [2, 5])
def test_process_constraints_are_in_every_strategy_and_the_count_is_the_brute_forces(tmp_path, seed):
    parts = partition((2, 2, 2), 6, seed)
    brute = BruteForce(parts, (2, 2, 2))
    sequence = next(s for s in itertools.permutations(brute.ids) if brute.feasible(s))
    wanted = [(sequence[1], sequence[4]), (sequence[0], sequence[2])]
    folder = write_assembly(tmp_path / "voxels", parts)
    req = {}
    for b, a in wanted:
        req.setdefault(a, []).append(b)
    (tmp_path / "process.yaml").write_text(json.dumps({"requires": req}))
    derived = derive(folder, manifest=tmp_path / "process.yaml")
    for pairs in requires_of(derived):
        assert set(wanted) <= closure(pairs)
    keeps = [s for s in itertools.permutations(brute.ids) if brute.feasible(s)
             and all(s.index(b) < s.index(a) for b, a in wanted)]
    assert Schedule(derived.plan).count() == len(keeps) > 0
    assert run_cli("derive", folder, "--manifest", tmp_path / "process.yaml").exit_code == 0


def test_base_and_fixture(tmp_path):
    """The plate as base: first in every sequence.  The plate as fixture: no part of the plan, and a
    direction it blocks is none (the bolts cannot come from below)."""
    folder = write_assembly(tmp_path / "bolts", BOLTS)
    brute = BruteForce(BOLTS, (3, 1, 3))
    based = derive(folder, base="plate")
    assert Schedule(based.plan).count() == sum(1 for s in itertools.permutations(brute.ids)
                                               if brute.feasible(s) and s[0] == "plate")
    fixed = derive(folder, fixture="plate")
    assert "plate" not in fixed.plan.part_ids
    assert Schedule(fixed.plan).count() == sum(1 for s in itertools.permutations(brute.ids)
                                               if brute.feasible(s) and s[0] == "plate")
    assert all("plate" not in q for dirs in fixed.blocking.blockers.values() for q in dirs.values())


MANIFEST_CASES = {
    "unknown key": ("quantity:\n  bolt: [b1, b2]\n", "assembly.yaml:1: unknown key 'quantity'",
                    "did you mean 'quantities'?"),
    "unknown instance": ("quantities:\n  bolt: [b1, b3]\n", "assembly.yaml:2: quantities.bolt: unknown instance 'b3'",
                         "the assembly's parts are b1, b2, cover, plate, spacer"),
    "unknown part": ("names:\n  cover: lid\n  spaser: ring\n", "assembly.yaml:3: names.spaser: unknown part",
                     "did you mean 'spacer'?"),
    "cycle": ("requires:\n  cover: [spacer]\n  spacer: [cover]\n", "process constraints in a cycle",
              "drop one of them"),
    "two parts": ("quantities:\n  bolt: [b1, b2]\n  pin: [b2, spacer]\n", "'b2' is an instance of 'bolt' and of 'pin'",
                  "under one part"),
    "one instance": ("quantities:\n  bolt: [b1]\n", "is not a list of 2 to 300 instance ids", "assembly.yaml:2"),
    "control": ("names:\n  cover: \"lid\\e[31m\"\n", "is not a display name (text): it holds a control character",
                "assembly.yaml:2"),
    "self": ("requires: {cover: [cover]}\n", "process constraints in a cycle: cover before cover", "assembly.yaml:1"),
    "direction": ("directions: [+x, up]\n", "directions.1: 'up' is not a direction", "[x, y, z]"),
    "zero direction": ("directions: [[0, 0, 0]]\n", "is not a direction", "assembly.yaml:1"),
    "many directions": ("directions: [" + ", ".join(f"[1, {i}, 0]" for i in range(65)) + "]\n",
                        "65 directions; a manifest lists at most 64", "assembly.yaml:1"),
    "not yaml": ("names: [a\n", "YAML syntax error", "assembly.yaml"),
    "aliases": ("a: &a [x, x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
                "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
                "e: [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\n", "alias", "assembly.yaml"),
    "fixture constrained": ("fixture: plate\nrequires: {cover: [plate]}\n", "the fixture is in place from the start",
                            "assembly.yaml:1"),
    "list": ("- names\n", "not a mapping of keys", "assembly.yaml"),
}


@pytest.mark.parametrize("case", sorted(MANIFEST_CASES))
def test_a_bad_manifest_is_refused_saying_where_and_what_to_do(tmp_path, case):
    folder = write_assembly(tmp_path / "bolts", BOLTS)
    text, *expected = MANIFEST_CASES[case]
    (folder / "assembly.yaml").write_text(text)
    out = fail_text(folder)
    assert all(e in out for e in expected), out
    assert "\x1b" not in out
    with pytest.raises(ManifestError):
        derive(folder)


def test_the_manifest_limits(tmp_path, monkeypatch):
    from opportune.derive import manifest

    folder = write_assembly(tmp_path / "bolts", BOLTS)
    (folder / "assembly.yaml").write_text("# " + "x" * 200 + "\n")
    monkeypatch.setattr(manifest, "MAX_MANIFEST_BYTES", 100)
    assert "203 bytes; a manifest has at most 100" in fail_text(folder)
    monkeypatch.setattr(manifest, "MAX_MANIFEST_BYTES", 1 << 20)
    monkeypatch.setattr(manifest, "MAX_PROCESS", 1)
    (folder / "assembly.yaml").write_text("requires: {cover: [b1, b2]}\n")
    assert "2 process constraints; a manifest has at most 1" in fail_text(folder)
    assert "no such file" in fail_text(folder, "--manifest", tmp_path / "nowhere.yaml")
    # a problem on each of 300 lines: every one kept, twenty shown, the rest counted
    (folder / "assembly.yaml").write_text("names:\n" + "".join(f"  p{i}: {i}\n" for i in range(300)))
    with pytest.raises(ManifestError) as caught:
        derive(folder)
    assert len(caught.value.problems) == 300 and str(caught.value).endswith("… 280 more problems")
    assert len(str(caught.value).splitlines()) == 21


def test_keywords_replace_the_manifest_and_are_checked_alike(tmp_path):
    folder = write_assembly(tmp_path / "bolts", BOLTS)
    brute = BruteForce(BOLTS, (3, 1, 3))
    (folder / "assembly.yaml").write_text("base: spacre\n")
    with pytest.raises(ManifestError, match="assembly.yaml:1: base: unknown part 'spacre'"):
        derive(folder)
    assert Schedule(derive(folder, base="cover").plan).count() == sum(
        1 for s in itertools.permutations(brute.ids) if brute.feasible(s) and s[0] == "cover")
    with pytest.raises(ManifestError, match="unknown part 'plat'"):
        derive(folder, base="plat")
    with pytest.raises(GeometryError, match="directions: 'diagonals' is not a direction"):
        derive(folder, directions="diagonals")
    with pytest.raises(ManifestError, match="not a direction"):
        derive(folder, directions=["+x", "+w"])


# ---------------------------------------------------------------- STEP (the step extra)

STEP = Path(__file__).parent / "data" / "three_boxes.step"   # made with gmsh's OpenCASCADE kernel, in mm


def test_a_step_file_derives_the_plan_of_its_products(tmp_path):
    """Three boxes in millimetres (a base of 2 x 1 x 1, two cubes on it), products named base, left,
    right: the same blockers as the OBJ files of the same boxes in millimetres."""
    pytest.importorskip("cascadio", reason="the step extra, which make test installs")
    step = derive(STEP)
    obj = derive(write_assembly(tmp_path / "obj", {"base": [(0, 0, 0), (1, 0, 0)], "left": [(0, 0, 1)],
                                                   "right": [(1, 0, 1)]}), units="mm")
    assert step.plan.part_ids == ("base", "left", "right")
    assert step.blocking.blockers == obj.blocking.blockers
    assert Schedule(step.plan).count() == Schedule(obj.plan).count() == 6


def test_a_hostile_step_file_is_refused(tmp_path, monkeypatch):
    pytest.importorskip("cascadio", reason="the step extra, which make test installs")
    from opportune.derive import scene

    (tmp_path / "bad.step").write_text("ISO-10303-21;\nHEADER;garbage\n")
    assert "bad.step: Open CASCADE could not mesh the STEP file" in fail_text(tmp_path / "bad.step")
    monkeypatch.setattr(scene, "MAX_STEP_BYTES", 1000)
    assert "at most 1,000 bytes" in fail_text(STEP)
    monkeypatch.setattr(scene, "MAX_STEP_BYTES", 1 << 20)
    # no time at all: the child is ended before any answer, whatever the machine's load (exit 1, saying so)
    monkeypatch.setattr(scene, "STEP_SECONDS", 0)
    assert "took over 0 s" in fail_text(STEP)


def _paths(value, path=()):
    """Every place in a JSON document (its keys' and items' paths)."""
    yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, path + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, path + (i,))


def test_a_glb_changed_anywhere_reads_or_is_refused_never_a_crash(tmp_path):
    """Every value of a valid scene's JSON replaced by junk of each kind, and bytes of its binary chunk
    flipped: each file reads, or is refused with a GeometryError (never another exception)."""
    import random

    from opportune.derive.scene import read_scene

    parts = {"a": [(0, 0, 0), (1, 0, 0)], "b": [(0, 1, 0)]}
    doc, binary = cube_doc([{"name": "product", "children": [1, 2]}, {"name": "a", "mesh": 0},
                            {"name": "b", "mesh": 0, "translation": [0, 1, 0], "scale": [1, 1, 1]}], [0])
    junk = [None, -1, 2**40, 1.5, 1e300, "x", [], {}, [0, 0], [1e300] * 4, True, float("inf")]
    places = [p for p in _paths(doc) if p]
    rng = random.Random(7)
    path = tmp_path / "fuzz.glb"
    for k in range(300):
        changed = json.loads(json.dumps(doc))
        where = rng.choice(places)
        target = changed
        for key in where[:-1]:
            target = target[key]
        target[where[-1]] = rng.choice(junk)
        data = bytearray(binary)
        if k % 3 == 0:
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        path.write_bytes(glb_bytes(changed, bytes(data)))
        try:
            read_scene(path, 1.0)
        except GeometryError:
            pass
    assert sorted(p.id for p in read_scene(write_glb(tmp_path / "ok.glb", parts), 1.0)) == ["a", "b"]


@pytest.mark.parametrize("scale", [1e300, 1e5])
def test_a_vertex_far_from_the_origin_is_refused_in_every_format(tmp_path, scale):
    """Coordinates of 1e300 (squares overflow) or 100 km: refused, naming the part and the units, without
    a warning on the way (the suite turns warnings into errors)."""
    folder = write_assembly(tmp_path / "far", {"a": [(0, 0, 0)]})
    (folder / "b.obj").write_text("\n".join(cube_lines([(0, 0, 0)])).replace("v 1", f"v {scale}") + "\n")
    assert "part 'b': vertex 5" in fail_text(folder) and "within 10,000 m" in fail_text(folder)
    nodes = [{"name": "a", "mesh": 0}, {"name": "b", "mesh": 0, "scale": [scale, 1, 1]}]
    (tmp_path / "far.glb").write_bytes(glb_bytes(*cube_doc(nodes, [0, 1])))
    assert "part 'b'" in fail_text(tmp_path / "far.glb") and "check the units" in fail_text(tmp_path / "far.glb")


def test_a_manifest_changed_anywhere_is_read_or_refused_never_a_crash():
    """Every value of a valid manifest replaced by junk of each kind: read, or a ManifestError."""
    import random

    from opportune.derive.manifest import check_parts, manifest_from

    doc = {"names": {"bolt": "M6", "cover": "lid"}, "quantities": {"bolt": ["b1", "b2"]}, "base": "plate",
           "directions": ["+x", [0, 1, -1]], "requires": {"cover": ["bolt", "spacer"]}}
    junk = [None, -1, 1e300, float("nan"), "x", "", "\x1b", [], {}, [[0]], [None], {"a": []}, True, "y" * 300]
    places = [p for p in _paths(doc) if p]
    rng = random.Random(11)
    for _ in range(400):
        changed = json.loads(json.dumps(doc))
        where = rng.choice(places)
        target = changed
        for key in where[:-1]:
            target = target[key]
        target[where[-1]] = rng.choice(junk)
        try:
            check_parts(manifest_from(changed), ["plate", "b1", "b2", "spacer", "cover"])
        except ManifestError as exc:
            assert "\x1b" not in str(exc)


def test_a_glb_with_every_triangle_on_its_own_vertices_and_no_indices(tmp_path):
    """Exporters repeat vertices along sharp edges (and may give no indices at all): vertices at one
    position are joined, so each cube is still one closed convex body."""
    parts = {"a": [(0, 0, 0)], "b": [(1, 0, 0)], "c": [(0, 0, 1)]}
    soup = CUBE_V[CUBE_F].reshape(-1, 3).astype("<f4").tobytes()
    nodes = [{"name": p, "mesh": 0, "translation": [x + 0.5 for x in cells[0]]} for p, cells in parts.items()]
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0, 1, 2]}], "nodes": nodes,
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 36, "type": "VEC3"}],
           "bufferViews": [{"buffer": 0, "byteLength": len(soup)}], "buffers": [{"byteLength": len(soup)}]}
    (tmp_path / "soup.glb").write_bytes(glb_bytes(doc, soup))
    derived = derive(tmp_path / "soup.glb")
    assert Schedule(derived.plan).count() == BruteForce(parts, (2, 1, 2)).count()
    assert derived.blocking.blockers == derive(write_assembly(tmp_path / "obj", parts)).blocking.blockers


def test_an_mjcf_model_with_includes_and_a_mesh_folder(tmp_path):
    """Bodies in an included file, a mesh found through the compiler's meshdir: read as MuJoCo reads them."""
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "cube.obj").write_text("\n".join(cube_lines([(0, 0, 0)])) + "\n")
    (tmp_path / "parts.xml").write_text(
        '<mujoco><worldbody><body name="a"><geom type="mesh" mesh="cube"/></body>'
        '<body name="b" pos="1 0 0"><geom type="box" size=".5 .5 .5" pos=".5 .5 .5"/></body></worldbody></mujoco>')
    (tmp_path / "main.xml").write_text('<mujoco><compiler meshdir="meshes"/><asset><mesh name="cube" file="cube.obj"/>'
                                       '</asset><include file="parts.xml"/></mujoco>')
    derived = derive(tmp_path / "main.xml")
    parts = {"a": [(0, 0, 0)], "b": [(1, 0, 0)]}
    assert derived.blocking.blockers == derive(write_assembly(tmp_path / "obj", parts)).blocking.blockers


def random_model(rng) -> str:
    """An MJCF model of two named bodies (one nested under an unnamed body) with primitive geoms, each
    frame turned by one of the five ways MJCF writes an orientation, under a random compiler."""
    angle = rng.choice(["degree", "radian"])
    seq = "".join(rng.choice(["xyz", "zyx", "XYZ", "zxz", "xYz"]))
    turn = 180 if angle == "degree" else np.pi

    def frame() -> str:
        pos = " ".join(f"{x:.4f}" for x in rng.uniform(-2, 2, 3))
        kind = rng.choice(["none", "quat", "axisangle", "euler", "xyaxes", "zaxis"])
        numbers = {"quat": rng.normal(size=4), "axisangle": list(rng.normal(size=3)) + [rng.uniform(-turn, turn)],
                   "euler": rng.uniform(-turn, turn, 3), "xyaxes": rng.normal(size=6), "zaxis": rng.normal(size=3)}
        extra = "" if kind == "none" else f' {kind}="{" ".join(f"{x:.4f}" for x in numbers[kind])}"'
        return f'pos="{pos}"{extra}'

    def geom() -> str:
        kind = rng.choice(["box", "cylinder", "capsule", "sphere", "ellipsoid"])
        size = " ".join(f"{x:.3f}" for x in rng.uniform(0.1, 0.5, 3 if kind in ("box", "ellipsoid") else 2))
        if kind in ("cylinder", "capsule") and rng.random() < 0.5:
            ends = " ".join(f"{x:.3f}" for x in rng.uniform(-1, 1, 6))
            return f'<geom type="{kind}" size="{size.split()[0]}" fromto="{ends}"/>'
        return f'<geom type="{kind}" size="{size}" {frame()}/>'

    return (f'<mujoco><compiler angle="{angle}" eulerseq="{seq}"/><worldbody>'
            f'<body name="a" {frame()}>{geom()}<body {frame()}>{geom()}{geom()}</body>{geom()}</body>'
            f'<body {frame()}><body name="b" {frame()}>{geom()}</body></body></worldbody></mujoco>')


@pytest.mark.parametrize("seed", range(12))
def test_the_mjcf_reader_without_mujoco_places_every_geom_where_mujoco_does(tmp_path, seed):
    """Two independent readings of one model: MuJoCo's compiler, and this project's reading of the XML
    (orientations as quat, axisangle, euler under any sequence and unit, xyaxes, zaxis; fromto)."""
    pytest.importorskip("mujoco", reason="the physics extra, which make test installs")
    from opportune.derive.mjcf import read_mjcf_assembly

    rng = np.random.default_rng(seed)
    (tmp_path / "m.xml").write_text(random_model(rng))
    ours = read_mjcf_assembly(tmp_path / "m.xml", use_mujoco=False, tolerance=0)
    theirs = read_mjcf_assembly(tmp_path / "m.xml", use_mujoco=True, tolerance=0)
    assert [p.id for p in ours.parts] == [p.id for p in theirs.parts] == ["a", "b"]
    for a, b in zip(ours.parts, theirs.parts):
        va, vb = (np.vstack([body.vertices for body in p.bodies]) for p in (a, b))
        va, vb = (v[np.lexsort(np.round(v, 6).T[::-1])] for v in (va, vb))
        assert va.shape == vb.shape and np.allclose(va, vb, atol=1e-7), a.id


def test_what_the_reader_without_mujoco_does_not_follow_is_refused_saying_so(tmp_path):
    from opportune.derive.mjcf import read_mjcf_assembly

    for xml, expected in [
        ('<mujoco><default><geom size="1"/></default><worldbody><body name="a"><geom/></body></worldbody></mujoco>',
         "needs MuJoCo's compiler"),
        ('<mujoco><worldbody><body name="a"><geom type="mesh" mesh="m"/></body></worldbody></mujoco>',
         "needs MuJoCo's compiler"),
        ('<mujoco><worldbody><body name="a"><geom size="x"/></body></worldbody></mujoco>', "is not 3 finite numbers"),
        ('<mujoco><worldbody><body name="a" quat="1 0 0 0" euler="0 0 1"><geom size="1"/></body></worldbody>'
         '</mujoco>', "keep one"),
        ('<mujoco><worldbody><geom type="box" size="1 1 1"/></worldbody></mujoco>', "named body"),
        ('<mujoco><worldbody><body name="a" quat="0 0 0 0"><geom size="1"/></body></worldbody></mujoco>', "degenerate"),
        ('<mujoco><worldbody><body name="a"><geom type="capsule" size="1" fromto="1 1 1 1 1 1"/></body></worldbody>'
         '</mujoco>', "degenerate")]:
        (tmp_path / "m.xml").write_text(xml)
        with pytest.raises(GeometryError, match=expected):
            read_mjcf_assembly(tmp_path / "m.xml", use_mujoco=False)


def test_three_identical_parts_count_a_sixth_of_their_instances_orders(tmp_path):
    """Three bolts in a row between a plate and a cover, along ±z: every sequence of part ids stands for
    3! sequences of instances, and the plan admits exactly the projections of the feasible ones."""
    parts = {"plate": [(x, 0, 0) for x in range(3)], "b1": [(0, 0, 1)], "b2": [(1, 0, 1)], "b3": [(2, 0, 1)],
             "cover": [(x, 0, 2) for x in range(3)]}
    brute = BruteForce(parts, (3, 1, 3))
    brute.swept = [m[4:] for m in brute.swept]
    merged = derive(write_assembly(tmp_path / "row", parts), directions=["+z", "-z"],
                    quantities={"bolt": ["b1", "b2", "b3"]})
    assert Schedule(merged.plan).count() * 6 == brute.count() == 48
    everything = set(itertools.permutations(["plate", "bolt", "bolt", "bolt", "cover"]))
    assert {s for s in everything if admits(merged.plan, s)} == projected(brute, {"bolt": ["b1", "b2", "b3"]})


def test_explain_adds_a_direction_with_the_fixture_in_place(tmp_path):
    """`derive --explain` measures a direction added with the fixture in place, as the derivation has it: the
    plate is no part, and a direction it blocks is none.  Derived on four axes, +x and -x added: each
    recount is the brute force's on five axes, with the plate first (the fixture) and out of the count."""
    from opportune.derive.explain import explain

    folder = write_assembly(tmp_path / "bolts", BOLTS)
    fixed = derive(folder, fixture="plate", directions="+y,-y,+z,-z")
    e = explain(fixed, fixed.assembly, directions={"+x": (1, 0, 0), "-x": (-1, 0, 0)}, time_limit=30)
    added = {f["name"]: f for f in e.frees if f["kind"] == "direction"}
    assert sorted(added) == ["+x", "-x"] and not e.unfinished
    brute = BruteForce(BOLTS, (3, 1, 3))
    names, swept = list(AXES), brute.swept
    for name, f in added.items():
        keep = [names.index(d) for d in ("+y", "-y", "+z", "-z", name)]
        brute.swept = [[m if k in keep else -1 for k, m in enumerate(masks)] for masks in swept]
        count = sum(1 for s in itertools.permutations(brute.ids) if brute.feasible(s) and s[0] == "plate")
        assert f["count"]["value"] == count, (name, f)
