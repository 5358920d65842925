"""Plans from geometry (`opportune derive`): the derived plan admits exactly the feasible sequences.

Random voxel assemblies (parts are unions of unit cubes partitioning a small block, written as OBJ
meshes, one closed cube a body) are derived and compared with an independent brute force: a dynamic
programme over subsets that sweeps each part's cubes along each axis on the voxel grid.  Counts are
equal, and sampled sequences are in the plan iff the brute force finds them feasible.  Touching faces
are everywhere in these assemblies: sliding along them must be allowed.
"""

from __future__ import annotations

import io
import itertools
import json
import random
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("trimesh", reason="the geometry extra, which make test installs")

from conftest import run_cli  # noqa: E402
from opportune.derive import DeriveError, GeometryError, derive  # noqa: E402
from opportune.derive.explain import explain  # noqa: E402
from opportune.derive.geometry import read_assembly  # noqa: E402
from opportune.engine import Schedule  # noqa: E402
from opportune.formats import load_plan  # noqa: E402

AXES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0), "+z": (0, 0, 1), "-z": (0, 0, -1)}
BLOCKS = [(2, 2, 3), (3, 3, 2), (2, 3, 2), (3, 2, 2), (2, 2, 2), (3, 3, 3)]


# ---------------------------------------------------------------- voxel assemblies


def cube_lines(cells, first: int = 1) -> list[str]:
    """OBJ lines of closed unit cubes, one body each (its own 8 vertices), outward triangles."""
    lines = []
    for n, (x, y, z) in enumerate(cells):
        lines += [f"v {x + i} {y + j} {z + k}" for i in (0, 1) for j in (0, 1) for k in (0, 1)]

        def v(i, j, k, base=first + 8 * n):
            return base + 4 * i + 2 * j + k

        quads = [(v(0, 0, 0), v(0, 0, 1), v(0, 1, 1), v(0, 1, 0)), (v(1, 0, 0), v(1, 1, 0), v(1, 1, 1), v(1, 0, 1)),
                 (v(0, 0, 0), v(1, 0, 0), v(1, 0, 1), v(0, 0, 1)), (v(0, 1, 0), v(0, 1, 1), v(1, 1, 1), v(1, 1, 0)),
                 (v(0, 0, 0), v(0, 1, 0), v(1, 1, 0), v(1, 0, 0)), (v(0, 0, 1), v(1, 0, 1), v(1, 1, 1), v(0, 1, 1))]
        for a, b, c, d in quads:
            lines += [f"f {a} {b} {c}", f"f {a} {c} {d}"]
    return lines


def write_assembly(folder: Path, parts: dict[str, list[tuple[int, int, int]]]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, cells in parts.items():
        (folder / f"{name}.obj").write_text("\n".join(cube_lines(cells)) + "\n")
    return folder


def partition(block: tuple[int, int, int], k: int, seed: int) -> dict[str, list[tuple[int, int, int]]]:
    """The block's cells cut into ``k`` connected parts, grown from random seeds (deterministic)."""
    rng = random.Random(seed)
    cells = list(itertools.product(*(range(n) for n in block)))
    owner = {c: i for i, c in enumerate(rng.sample(cells, k))}
    while len(owner) < len(cells):
        c, p = rng.choice(sorted(owner.items()))
        x, y, z = c
        nxt = [(x + dx, y + dy, z + dz) for dx, dy, dz in AXES.values()]
        free = [n for n in nxt if n in set(cells) and n not in owner]
        if free:
            owner[rng.choice(free)] = p
    parts: dict[str, list] = {}
    for c, p in sorted(owner.items()):
        parts.setdefault(f"p{p:02d}", []).append(c)
    return parts


class BruteForce:
    """Feasible sequences on the voxel grid: a part goes in along d iff no cell it sweeps (its cells
    moved by -t·d, t ≥ 1, within the block) belongs to a part already in.  With ``gravity`` (down is -z)
    a part also needs a cell on the floor (z = 0) or a cell right on top of a cell of a part already
    in; with ``connected``, unless it is the first, a cell face to face with one of a part already in;
    with a ``base``, the base first, needing nothing."""

    def __init__(self, parts, block, gravity=False, connected=False, base=None):
        self.ids = sorted(parts)
        owner = {c: self.ids.index(p) for p, cells in parts.items() for c in cells}
        self.first = None if base is None else self.ids.index(base)
        self.needs = []          # per part, per requirement: the mask of parts any one of which holds it, waived first
        for p in self.ids:
            me, needs = self.ids.index(p), []
            if gravity and all(z > 0 for _, _, z in parts[p]):
                needs.append((sum(1 << q for q in {owner.get((x, y, z - 1), me) for x, y, z in parts[p]} - {me}),
                              False))
            if connected:
                needs.append((sum(1 << q for q in {owner.get(n, me) for c in parts[p] for n in neighbours(c)} - {me}),
                              True))
            self.needs.append(needs)
        self.swept = []          # per part, per direction: the mask of parts its sweep meets
        for p in self.ids:
            masks = []
            for d in AXES.values():
                mask = 0
                for c in parts[p]:
                    t = 1
                    while True:
                        cell = tuple(c[i] - t * d[i] for i in range(3))
                        if not all(0 <= cell[i] < block[i] for i in range(3)):
                            break
                        if cell in owner:       # a block with empty cells (the free cube's row)
                            mask |= 1 << owner[cell]
                        t += 1
                masks.append(mask & ~(1 << self.ids.index(p)))
            self.swept.append(masks)

    def fits(self, i: int, built: int) -> bool:
        if built == 0:                   # nothing in the way; the base first, or a part on the floor
            return i == self.first if self.first is not None else all(waived for _, waived in self.needs[i])
        held = i == self.first or all(n & built for n, _ in self.needs[i])
        return held and any(not (m & built) for m in self.swept[i])

    def count(self) -> int:
        n = len(self.ids)

        @lru_cache(maxsize=None)
        def f(built: int) -> int:
            if built == (1 << n) - 1:
                return 1
            return sum(f(built | 1 << i) for i in range(n) if not built >> i & 1 and self.fits(i, built))
        return f(0)

    def feasible(self, sequence) -> bool:
        built = 0
        for p in sequence:
            i = self.ids.index(p)
            if not self.fits(i, built):
                return False
            built |= 1 << i
        return True


def neighbours(c):
    return [tuple(c[i] + d[i] for i in range(3)) for d in AXES.values()]


def admits(plan, sequence) -> bool:
    s = Schedule(plan)
    for p in sequence:
        if p not in s.installable():
            return False
        s = s.install(p)
    return True


def closure(pairs) -> set[tuple[str, str]]:
    """All pairs an order implies (a plain fixed point: the orders here are small)."""
    closed = set(pairs)
    while True:
        more = {(a, d) for a, b in closed for c, d in closed if b == c} - closed
        if not more:
            return closed
        closed |= more


def assert_minimal(strategies) -> None:
    """No strategy's sequences contain another's (no closure inside another), no redundant constraint."""
    closures = [closure(p) for p in strategies]
    for i, ci in enumerate(closures):
        assert all(not (cj <= ci) for j, cj in enumerate(closures) if j != i), "a dominated strategy"
        for pair in strategies[i]:
            assert pair not in closure(set(strategies[i]) - {pair}), f"redundant constraint {pair}"


# ---------------------------------------------------------------- the exact plan


MODES = {"axes": {}, "gravity": {"gravity": "-z"}, "connected": {"connected": True},
         "gravity, connected": {"gravity": "-z", "connected": True}, "connected, base": {"connected": True, "base": 0}}


@pytest.mark.parametrize("mode", sorted(MODES))
@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(block=st.sampled_from(BLOCKS), k=st.integers(2, 12), seed=st.integers(0, 2**32 - 1))
def test_random_voxel_assemblies_admit_exactly_the_feasible_sequences(tmp_path_factory, mode, block, k, seed):
    """``derive --directions axes`` (with ``--gravity -z``, ``--connected``, ``--base``) against the brute force:
    equal counts, sampled sequences of the plan feasible, random orders in the plan iff feasible.  A plan
    refused for its size must be a feasible assembly (else the refusal names the lock); hypothesis fails
    the test if too few examples fit (its filter health check), so the comparisons are not vacuous."""
    k = min(k, block[0] * block[1] * block[2])
    parts = partition(block, k, seed)
    folder = write_assembly(tmp_path_factory.mktemp("voxels"), parts)
    options = dict(MODES[mode])
    if "base" in options:                   # the part at the block's corner
        options["base"] = next(p for p, cells in parts.items() if (0, 0, 0) in cells)
    brute = BruteForce(parts, block, gravity="gravity" in options, connected="connected" in options,
                       base=options.get("base"))
    try:
        derived = derive(folder, directions="axes", **options)
    except DeriveError as exc:
        if brute.count() == 0:
            assert "lock each other" in str(exc) or "no feasible sequence meets the supports" in str(exc), str(exc)
            return
        assert "strategies" in str(exc) and "no approximation" in str(exc), str(exc)
        assume(False)        # too large for a plan: not a comparison
    assert_admits_exactly(derived, brute, seed)


def assert_admits_exactly(derived, brute, seed) -> None:
    plan = derived.plan
    assert_minimal([s.pairs for s in derived.strategies])
    if len(plan.strategies) <= 12:          # the engine counts up to 12 strategies exactly (and estimates beyond)
        assert Schedule(plan).count() == brute.count() > 0
        for k in range(20):                 # sequences of the plan are feasible ...
            seq = Schedule(plan).sample(seed=k)
            assert brute.feasible(seq), seq
    rng = random.Random(seed)
    for _ in range(40):                     # ... and a random order is in the plan iff it is feasible
        seq = list(brute.ids)
        rng.shuffle(seq)
        assert admits(plan, seq) == brute.feasible(seq), seq
    for _ in range(20):                     # ... and the brute force's random walks: in it iff they finish
        built, seq = 0, []
        while len(seq) < len(brute.ids):
            fits = [i for i in range(len(brute.ids)) if not built >> i & 1 and brute.fits(i, built)]
            if not fits:
                break
            i = rng.choice(fits)
            built |= 1 << i
            seq.append(brute.ids[i])
        # a walk stuck before the end is a prefix no completion follows: the plan never lets it in
        assert admits(plan, seq) == (len(seq) == len(brute.ids)), seq


def test_sliding_along_touching_faces_is_allowed(tmp_path):
    """Two slabs, one on the other, and a cube set into the top one: every part slides out sideways
    along the faces it touches, so no order is forced."""
    parts = {"base": [(x, y, 0) for x in range(2) for y in range(2)], "left": [(0, 0, 1), (0, 1, 1)],
             "right": [(1, 0, 1), (1, 1, 1)]}
    derived = derive(write_assembly(tmp_path / "slabs", parts))
    assert Schedule(derived.plan).count() == 6 == BruteForce(parts, (2, 2, 2)).count()
    # but the base cannot come in from above once a slab is on it: blocked along -z by both slabs
    assert derived.blocking.blockers["base"]["-z"] == {"left", "right"}
    assert derived.blocking.blockers["base"]["+x"] == set()


def test_a_peg_in_a_hole_goes_in_one_way(tmp_path):
    """A ring of 8 cubes around a peg: the peg goes in along ±z only, and the ring blocks nothing of its own."""
    ring = [(x, y, 0) for x in range(3) for y in range(3) if (x, y) != (1, 1)]
    derived = derive(write_assembly(tmp_path / "peg", {"ring": ring, "peg": [(1, 1, 0)]}))
    peg = derived.blocking.blockers["peg"]
    assert {d for d, q in peg.items() if not q} == {"+z", "-z"}
    assert Schedule(derived.plan).count() == 2


# Two parts of a 3 × 3 × 2 block hooked into each other (found by the brute force among random
# partitions): neither can go in last along any axis.
LOCKED = {"hook": [(0, 0, 0), (1, 0, 0), (1, 1, 0), (1, 1, 1), (2, 0, 0), (2, 0, 1), (2, 1, 1), (2, 2, 1)],
          "eye": [(0, 0, 1), (0, 1, 0), (0, 1, 1), (0, 2, 0), (0, 2, 1), (1, 0, 1), (1, 2, 0), (1, 2, 1), (2, 1, 0),
                  (2, 2, 0)]}


def test_an_interlocked_assembly_is_refused_naming_the_parts(tmp_path):
    """The locked pair plus a free cube beside it: refused, naming the pair and not the cube."""
    parts = {**LOCKED, "free": [(3, 0, 0)]}
    assert BruteForce(parts, (4, 3, 2)).count() == 0
    r = run_cli("derive", write_assembly(tmp_path / "lock", parts))
    assert r.exit_code == 1
    text = " ".join(r.output.split())
    assert "lock each other" in text and "eye, hook" in text and "free" not in text.split(":")[-1].split("lock")[0]
    with pytest.raises(DeriveError, match="parts eye, hook lock each other"):
        derive(tmp_path / "lock")


def test_the_derived_plan_checks_and_counts_on_the_command_line(tmp_path):
    parts = partition((2, 2, 3), 6, seed=7)
    folder = write_assembly(tmp_path / "six", parts)
    out = tmp_path / "six.yaml"
    r = run_cli("derive", folder, "-o", out)
    assert r.exit_code == 0, r.output
    assert run_cli("check", out).exit_code == 0
    counted = run_cli("count", out, "--json")
    assert json.loads(counted.output)["sequences"] == str(BruteForce(parts, (2, 2, 3)).count())
    doc = json.loads(run_cli("derive", folder, "--json").output)
    assert doc["parts"] == 6 and doc["directions"] == list(AXES) and doc["blocking_checks"] > 0
    assert load_plan(out).part_ids == tuple(sorted(parts))


def test_several_strategies_each_one_direction_choice(tmp_path):
    """A 3 × 3 × 3 block cut in 8 parts whose exact plan needs 4 strategies (none containing another)."""
    parts = partition((3, 3, 3), 8, seed=0)
    derived = derive(write_assembly(tmp_path / "eight", parts))
    assert len(derived.strategies) == len(derived.plan.strategies) == 4
    assert_minimal([s.pairs for s in derived.strategies])
    assert Schedule(derived.plan).count() == BruteForce(parts, (3, 3, 3)).count()
    # each strategy's order is the one its directions force: p before every part blocking p along its direction
    for s in derived.strategies:
        forced = {(p, q) for p, d in s.directions.items() for q in derived.blocking.blockers[p][d]}
        assert closure(forced) == closure(s.pairs)


# ---------------------------------------------------------------- parts that are not convex, as one surface

FACES = [(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1)]     # cube_lines's quads, in order


def surface_lines(cells) -> list[str] | None:
    """OBJ lines of a union of unit cubes as one closed surface (the faces between its own cubes left out,
    vertices shared), or None when that surface has an edge shared by four faces (cubes meeting along an
    edge only: not a 2-manifold)."""
    cells = set(cells)
    index: dict[tuple, int] = {}
    lines, faces, directed = [], [], []
    for x, y, z in sorted(cells):
        quads = cube_lines([(x, y, z)])[-12:]           # its 12 triangles, vertices 1..8 of this cube
        corner = [(x + i, y + j, z + k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        for f, (dx, dy, dz) in enumerate(FACES):
            if (x + dx, y + dy, z + dz) in cells:
                continue
            for tri in quads[2 * f:2 * f + 2]:
                ids = []
                for v in (int(w) for w in tri.split()[1:]):
                    point = corner[v - 1]
                    if point not in index:
                        index[point] = len(index) + 1
                        lines.append("v {} {} {}".format(*point))
                    ids.append(index[point])
                faces.append("f {} {} {}".format(*ids))
                directed += [(ids[0], ids[1]), (ids[1], ids[2]), (ids[2], ids[0])]
    if len(set(directed)) != len(directed):
        return None
    return lines + faces


@pytest.mark.parametrize("seed", range(4))
def test_parts_written_as_one_surface_that_is_not_convex_block_as_their_cubes(tmp_path, seed):
    """Each part of a random voxel block written as one closed surface (not convex: tested by manifold3d)
    blocks, touches and counts exactly as the same part written as convex cubes (the separating axes),
    and as the brute force; with --gravity and --connected the supports (from the surfaces' triangles)
    are the same too."""
    parts = partition((3, 3, 2), 6, seed)
    cubes = derive(write_assembly(tmp_path / "cubes", parts), directions="axes", gravity="-z", connected=True)
    folder = tmp_path / "surfaces"
    folder.mkdir()
    shapes = 0
    for name, cells in parts.items():
        lines = surface_lines(cells)
        shapes += lines is not None and len(cells) > 1
        (folder / f"{name}.obj").write_text("\n".join(lines or cube_lines(cells)) + "\n")
    assert shapes >= 3
    surfaces = derive(folder, directions="axes", gravity="-z", connected=True)
    assert any(not b.convex for p in read_assembly(folder).parts for b in p.bodies)
    assert surfaces.blocking.blockers == cubes.blocking.blockers
    assert surfaces.conditions == cubes.conditions
    brute = BruteForce(parts, (3, 3, 2), gravity=True, connected=True)
    if len(surfaces.strategies) <= 12:
        assert Schedule(surfaces.plan).count() == Schedule(cubes.plan).count() == brute.count()


# ---------------------------------------------------------------- hostile meshes: exit 1, a message, no traceback


def cube_text(x=0) -> str:
    return "\n".join(cube_lines([(x, 0, 0)])) + "\n"


HOSTILE = {
    "nan": ("v nan 0 0\n" + cube_text().split("\n", 1)[1], "not a finite number"),
    "inf": (cube_text().replace("v 1 1 1", "v inf 1 1"), "not a finite number"),
    "empty": ("", "part 'bad'"),
    "not a mesh": ("\x00\x01garbage \xff\xfe" * 50, "part 'bad'"),
    "degenerate": (cube_text() + "v 5 5 5\nv 6 6 6\nv 7 7 7\nf 9 10 11\n", "degenerate"),
    "open": ("\n".join(cube_text().splitlines()[:-2]) + "\n", "not a closed surface"),
    # closed and oriented, but a corner pushed through the opposite face: the surface passes through itself
    "crossing": (cube_text().replace("v 1 1 1", "v 0.2 0.3 -0.8"), "bad.obj: part 'bad': body 1 crosses itself"),
    "crossing a side": (cube_text().replace("v 1 1 1", "v -0.5 1.2 1.3"), "crosses itself (its triangles 1 and 3"),
    "half turned": ("".join(line if not line.startswith("f") or i % 3 else "f " + " ".join(line.split()[:0:-1]) + "\n"
                            for i, line in enumerate(cube_text().splitlines(True))), "triangles facing opposite ways"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_mesh_is_refused_naming_the_part(tmp_path, case):
    text, expected = HOSTILE[case]
    folder = tmp_path / "hostile"
    write_assembly(folder, {"good": [(3, 0, 0)]})
    (folder / "bad.obj").write_bytes(text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text)
    r = run_cli("derive", folder)
    assert r.exit_code == 1, r.output
    out = " ".join(r.output.split())
    assert "error:" in out and "'bad'" in out and expected in out, out
    with pytest.raises(GeometryError):
        derive(folder)


def test_a_surface_through_itself_is_refused_as_stl_too_and_a_dent_or_an_inward_file_is_not(tmp_path):
    """The crossing check is on every body however read (an STL's vertices joined by position); a cube with a
    corner pushed in (not convex, a valid solid) and a cube written inside out (turned as read) derive."""
    import trimesh

    folder = write_assembly(tmp_path / "stl", {"good": [(3, 0, 0)]})
    crossing = trimesh.load(io.StringIO(HOSTILE["crossing"][0]), file_type="obj", process=False)
    crossing.export(folder / "bad.stl")
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "bad.stl: part 'bad': body 1 crosses itself" in " ".join(r.output.split()), r.output
    (folder / "bad.stl").unlink()
    (folder / "dent.obj").write_text(cube_text().replace("v 1 1 1", "v 0.5 0.5 0.5"))
    inward = [line if not line.startswith("f") else "f " + " ".join(line.split()[:0:-1]) for line in cube_lines([(0, 2, 0)])]
    (folder / "inward.obj").write_text("\n".join(inward) + "\n")
    assert run_cli("derive", folder).exit_code == 0
    bodies = {p.id: p.bodies for p in read_assembly(folder).parts}
    assert not bodies["dent"][0].convex and bodies["inward"][0].convex


def test_a_convex_surface_covering_its_hull_twice_is_refused():
    """The convex bodies' check (their triangles' volume against their hull's): a tetrahedron's surface
    written twice over is closed, faces out and passes the convexity test, but covers its hull twice."""
    from opportune.derive.geometry import Body, _check_not_crossing

    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    once = Body(corners, np.eye(3), np.eye(3), faces, True)
    _check_not_crossing("t", 1, once, np.arange(4))
    with pytest.raises(GeometryError, match="part 't': body 1 crosses itself .*cover its hull 2 times"):
        _check_not_crossing("t", 1, Body(corners, np.eye(3), np.eye(3), np.vstack([faces, faces]), True), np.arange(8))


def test_a_binary_stl_that_is_noise_is_refused(tmp_path):
    folder = tmp_path / "stl"
    folder.mkdir()
    (folder / "noise.stl").write_bytes(bytes(random.Random(3).randrange(256) for _ in range(600)))
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "'noise'" in r.output


def test_parts_that_interpenetrate_are_refused_naming_both(tmp_path):
    folder = write_assembly(tmp_path / "overlap", {"a": [(0, 0, 0)]})
    (folder / "b.obj").write_text(cube_text().replace("v 0 ", "v 0.5 ").replace("v 1 ", "v 1.5 "))
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "'a' and 'b' overlap by 0.5" in " ".join(r.output.split())
    # within a tolerance larger than the overlap they are accepted
    assert run_cli("derive", folder, "--tolerance", "0.6").exit_code == 0


def test_the_limits_are_checked_before_the_work(tmp_path, monkeypatch):
    from opportune.derive import geometry

    folder = write_assembly(tmp_path / "many", {f"c{i}": [(i, 0, 0)] for i in range(4)})
    monkeypatch.setattr(geometry, "MAX_MESH_PARTS", 3)
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "at most 3 parts" in r.output
    monkeypatch.setattr(geometry, "MAX_MESH_PARTS", 300)
    monkeypatch.setattr(geometry, "MAX_TRIANGLES", 11)
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "12 triangles" in r.output and "at most 11" in r.output
    monkeypatch.setattr(geometry, "MAX_MESH_BYTES", 100)
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "'c0'" in r.output and "at most 100 bytes" in r.output


def test_units_and_a_missing_folder(tmp_path):
    folder = write_assembly(tmp_path / "mm", {"a": [(0, 0, 0)], "b": [(1, 0, 0)]})
    doc = json.loads(run_cli("derive", folder, "--units", "mm", "--json").output)
    assert doc["tolerance_m"] == pytest.approx(1e-6 * 3 ** 0.5 * 2 ** 0.5 * 1e-3, rel=0.01) or doc["tolerance_m"] > 0
    r = run_cli("derive", tmp_path / "nowhere")
    assert r.exit_code == 1 and "not a folder" in r.output
    r = run_cli("derive", folder, "--units", "inch")
    assert r.exit_code == 1 and "units 'inch'" in r.output


def test_an_exact_plan_larger_than_a_plan_holds_is_written_as_ways_and_refused_as_strategies(tmp_path, monkeypatch):
    from opportune.derive import plan as derive_plan

    folder = write_assembly(tmp_path / "eight", partition((3, 3, 3), 8, seed=0))     # 4 strategies exactly
    exact = Schedule(derive(folder).plan).count()
    monkeypatch.setattr(derive_plan, "MAX_STRATEGIES", 3)
    r = run_cli("derive", folder)
    assert r.exit_code == 0 and "needs 4 strategies" in r.output and "at most 3" in r.output
    assert "\nways:" in r.output
    with pytest.raises(DeriveError, match="needs 4 strategies.*no approximation"):
        derive(folder, form="strategies")
    ways = derive(folder)
    assert "a plan holds at most 3: the plan is written as each part's ways in instead" in ways.notes[0]
    assert ways.plan.is_ways and not ways.strategies and Schedule(ways.plan).count() == exact
    monkeypatch.setattr(derive_plan, "MAX_STRATEGIES", 4)
    assert not derive(folder).plan.is_ways
    monkeypatch.setattr(derive_plan, "MAX_WORKING", 3)
    r = run_cli("derive", folder, "--json")
    doc = json.loads(r.output)
    assert r.exit_code == 0 and "ways" in doc["plan"] and "strategies" not in doc["plan"]
    assert any("union of more than 3 incomparable partial orders" in n and "p02 (4)" in n for n in doc["notes"])
    with pytest.raises(DeriveError, match="form 'orders'"):
        derive(folder, form="orders")
    r = run_cli("derive", folder, "--explain", "--figure", tmp_path / "ways.svg")   # read from the ways
    assert r.exit_code == 0 and "8 parts, written as each part's ways in" in r.output
    assert "wrote the exploded view (one feasible sequence)" in r.output and (tmp_path / "ways.svg").stat().st_size


@pytest.mark.parametrize("mode", sorted(MODES))
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(block=st.sampled_from(BLOCKS), k=st.integers(2, 12), seed=st.integers(0, 2**32 - 1))
def test_random_voxel_assemblies_written_as_ways_admit_exactly_the_feasible_sequences(tmp_path_factory, mode, block,
                                                                                       k, seed):
    """The same comparison with the plan forced to the ways form (what derive writes where the union of
    partial orders is too large): its count, samples, random orders and the brute force's walks."""
    k = min(k, block[0] * block[1] * block[2])
    parts = partition(block, k, seed)
    folder = write_assembly(tmp_path_factory.mktemp("voxels"), parts)
    options = dict(MODES[mode])
    if "base" in options:
        options["base"] = next(p for p, cells in parts.items() if (0, 0, 0) in cells)
    brute = BruteForce(parts, block, gravity="gravity" in options, connected="connected" in options,
                       base=options.get("base"))
    try:
        derived = derive(folder, directions="axes", form="ways", **options)
    except DeriveError as exc:
        assert brute.count() == 0, str(exc)
        return
    assert derived.plan.is_ways
    assert load_plan_text(derived.plan) == derived.plan       # what derive writes reads back the same
    assert Schedule(derived.plan).count() == brute.count() > 0
    for k in range(10):
        assert brute.feasible(Schedule(derived.plan).sample(seed=k))
    assert_admits_exactly(derived, brute, seed)


def load_plan_text(plan):
    from opportune.formats.loader import plan_from_dict

    return plan_from_dict(json.loads(json.dumps(plan.to_dict())), file=plan.source)


@pytest.mark.parametrize("suffix", [".stl", ".ply"])
def test_stl_and_ply_read_as_obj(tmp_path, suffix):
    """Parts of one cube each, exported by trimesh as STL (no shared vertices) or PLY, in millimetres:
    the same blockers and the same count as the OBJ files in metres."""
    import trimesh

    cells = {f"c{i}": [c] for i, c in enumerate(itertools.product(range(2), range(2), range(2)))}
    cells["c8"] = [(2, 0, 0)]
    obj = derive(write_assembly(tmp_path / "obj", cells))
    other = tmp_path / "other"
    other.mkdir()
    for f in (tmp_path / "obj").iterdir():
        mesh = trimesh.load(str(f), force="mesh", process=False)
        mesh.apply_scale(1000.0)
        mesh.export(str(other / (f.stem + suffix)))
    derived = derive(other, units="mm")
    assert derived.blocking.blockers == obj.blocking.blockers
    assert Schedule(derived.plan).count() == Schedule(obj.plan).count() == BruteForce(cells, (3, 2, 2)).count()


# ---------------------------------------------------------------- the separating-axis test off the grid


def hull_body(points):
    """A Body of the convex hull of ``points`` (scipy), with its facets' outward normals and edge directions."""
    from scipy.spatial import ConvexHull

    from opportune.derive.geometry import Body

    hull = ConvexHull(points)
    simplices = hull.simplices
    edges = points[simplices[:, [1, 2, 0]]] - points[simplices]
    edges = edges.reshape(-1, 3)
    edges /= np.linalg.norm(edges, axis=1)[:, None]
    return Body(points[hull.vertices], hull.equations[:, :3], edges), hull.equations


def lp_overlap(eq_a, eq_b, sweep) -> float:
    """An independent measure: the largest margin s with x inside A and x + t·sweep inside B (t ≥ 0), both
    by s (linear programming); positive iff the swept A and B share interior points."""
    from scipy.optimize import linprog

    na, oa, nb, ob = eq_a[:, :3], eq_a[:, 3], eq_b[:, :3], eq_b[:, 3]
    # variables x (3), t, s: maximise s
    rows = np.vstack([np.hstack([na, np.zeros((len(na), 1)), np.ones((len(na), 1))]),
                      np.hstack([nb, (nb @ sweep)[:, None], np.ones((len(nb), 1))])])
    res = linprog([0, 0, 0, 0, -1], A_ub=rows, b_ub=np.concatenate([-oa, -ob]),
                  bounds=[(None, None)] * 3 + [(0, None), (None, 1)], method="highs")
    assert res.status == 0, res.message
    return -res.fun


@settings(max_examples=200, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), axis=st.sampled_from(list(AXES)))
def test_the_swept_overlap_of_random_convex_bodies_agrees_with_linear_programming(seed, axis):
    """Random tilted polytopes (hulls of random points): the separating-axis depth is positive exactly
    when a linear programme finds a common interior point of the swept body and the other."""
    pytest.importorskip("scipy")
    rng = np.random.default_rng(seed)
    a, eq_a = hull_body(rng.normal(size=(8, 3)))
    b, eq_b = hull_body(rng.normal(size=(8, 3)) + rng.uniform(-3, 3, size=3))
    sweep = -np.array(AXES[axis], float)
    from opportune.derive.blocking import depth

    deep, margin = depth(a, b, sweep), lp_overlap(eq_a, eq_b, sweep)
    if abs(deep) > 1e-7 and abs(margin) > 1e-7:
        assert (deep > 0) == (margin > 0), (deep, margin)
    if margin > 0:       # a ball of radius s inside both: on every axis their projections share 2s at least
        assert deep >= 2 * margin - 1e-9


def test_a_file_name_the_plan_refuses_as_a_part_id_is_refused_escaped(tmp_path):
    """Part ids are the files' stems: one with a control character is refused by the plan's own check,
    with exit 1 and the character escaped (never sent raw to the terminal)."""
    folder = write_assembly(tmp_path / "names", {"x\x1b[31my": [(0, 0, 0)], "b": [(1, 0, 0)]})
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "\x1b" not in r.output and "rename the files" in " ".join(r.output.split())
    with pytest.raises(DeriveError, match="control character"):
        derive(folder)


# ---------------------------------------------------------------- options: directions, supports, a base


def test_directions_as_a_list_and_refused_directions(tmp_path):
    folder = write_assembly(tmp_path / "two", {"a": [(0, 0, 0)], "b": [(1, 0, 0)]})
    doc = json.loads(run_cli("derive", folder, "--directions", "+z, -x,0 0.7 0.7", "--json").output)
    assert doc["directions"] == ["+z", "-x", "0 0.707107 0.707107"]
    # a coming in moving -x (from the +x side) passes through b; b coming the same way meets nothing
    assert doc["blockers"]["a"]["-x"] == ["b"] and doc["blockers"]["b"]["-x"] == []
    for bad, said in [("up", "'up' is not a direction"), ("0 0 0", "'0 0 0' is not a direction"),
                      ("1 nan 0", "is not a direction"), (",".join(["1 2 %d" % k for k in range(70)]), "at most 64")]:
        r = run_cli("derive", folder, "--directions", bad)
        assert r.exit_code == 1 and said in r.output, r.output
    r = run_cli("derive", folder, "--base", "nope")
    assert r.exit_code == 1 and "base: unknown part 'nope'" in r.output
    r = run_cli("derive", folder, "--gravity", "+z,-z")
    assert r.exit_code == 1 and "give one direction" in r.output


def test_a_part_nothing_holds_under_gravity_is_refused_naming_it(tmp_path):
    """Two cubes floating beside a tower (nothing under them, touching nothing below): under gravity
    neither can ever go in; without gravity every order is feasible."""
    parts = {"floor": [(0, 0, 0)], "top": [(0, 0, 1)], "hang": [(1, 0, 1)], "hung": [(2, 0, 1)]}
    folder = write_assembly(tmp_path / "hang", parts)
    r = run_cli("derive", folder, "--gravity", "-z")
    said = " ".join(r.output.split())
    assert r.exit_code == 1 and "no feasible sequence meets the supports" in said
    assert "hang rests on no part" in said and "can never go in" in said     # named, with why
    assert BruteForce(parts, (3, 1, 2), gravity=True).count() == 0
    assert run_cli("derive", folder).exit_code == 0
    # connected alone: hang touches top, hung touches hang: feasible
    derived = derive(folder, connected=True)
    brute = BruteForce(parts, (3, 1, 2), connected=True)
    assert Schedule(derived.plan).count() == brute.count() > 0


# ---------------------------------------------------------------- why no sequence meets the supports

#: A gear that rests only on its shaft, inside a housing: the shaft runs along x through holes in the
#: housing's two walls and rests on them; the gear rings the shaft in the y-z plane between the walls (the
#: housing's floor has a hole under it). Along ±x the walls are in the gear's way, along ±y and ±z the
#: shaft: the gear must come before the shaft and the housing, yet it rests on the shaft alone.
GEARED = {"housing": [(x, y, 0) for x in range(3) for y in range(3) if (x, y) != (1, 1)]
          + [(x, y, z) for x in (0, 2) for y in range(3) for z in (1, 2, 3) if (y, z) != (1, 2)],
          "shaft": [(0, 1, 2), (1, 1, 2), (2, 1, 2)], "gear": [(1, 1, 1), (1, 0, 2), (1, 2, 2), (1, 1, 3)]}


def test_supports_that_no_sequence_meets_are_refused_naming_the_parts_and_why(tmp_path):
    folder = write_assembly(tmp_path / "geared", GEARED)
    assert BruteForce(GEARED, (3, 3, 4), gravity=True).count() == 0
    r = run_cli("derive", folder, "--gravity", "-z")
    said = " ".join(r.output.split())
    assert r.exit_code == 1 and "no feasible sequence meets the supports" in said
    # each order of the contradiction named with its reason: the gear's only support, its way blocked
    assert "shaft before gear (gear can rest only on shaft)" in said, said
    assert "gear must come before housing (along +x housing is in gear's way" in said, said
    assert "along +y shaft is in its way and must come before it" in said, said
    based = run_cli("derive", folder, "--gravity", "-z", "--base", "housing")
    said = " ".join(based.output.split())
    assert based.exit_code == 1 and "no feasible sequence keeps the process constraints" in said
    assert "housing before gear (housing is the base: it goes first)" in said, said
    assert "gear must come before shaft" in said and "gear can rest only on shaft" in said, said
    free = derive(folder, directions="axes")        # without gravity the gear floats: feasible
    assert Schedule(free.plan).count() == BruteForce(GEARED, (3, 3, 4)).count() > 0


def ways_of(folder: Path, **options):
    """The ways in of a voxel assembly's parts (axes), with its supports, as the plan is built from them."""
    from opportune.derive.blocking import AXES as AXIS_VECTORS, find_blocking
    from opportune.derive.contacts import find_contacts
    from opportune.derive.directions import support_conditions
    from opportune.derive.plan import alternatives

    assembly = read_assembly(folder)
    conditions = support_conditions(assembly, find_contacts(assembly), **options)
    return alternatives(find_blocking(assembly, AXIS_VECTORS), conditions), conditions


@pytest.mark.parametrize("options", [{"gravity": "-z"}, {"gravity": "-z", "connected": True},
                                     {"gravity": "-z", "base": True}, {"connected": True, "base": True}])
@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(block=st.sampled_from(BLOCKS), k=st.integers(2, 6), seed=st.integers(0, 2**32 - 1))
def test_the_orders_a_refusal_states_hold_in_every_feasible_sequence(tmp_path_factory, options, block, k, seed):
    """The necessary orders the refusal reasons from, against the brute force's feasible sequences (all
    orders of up to six parts): each is kept by every feasible sequence, and a contradiction is stated
    only where there is none.  A third of the cells are left empty, so that parts hang (on 400 such
    assemblies a quarter had no feasible sequence, and all but 2 of those 93 were named)."""
    from opportune.derive.refusals import necessary_orders

    parts = partition(block, min(k, block[0] * block[1] * block[2]), seed)
    holes = random.Random(seed)
    parts = {p: [c for c in cells if holes.random() > 0.3] or cells[:1] for p, cells in parts.items()}
    folder = write_assembly(tmp_path_factory.mktemp("voxels"), parts)
    options = dict(options)
    if options.pop("base", False):
        options["base"] = min(parts, key=lambda p: min(parts[p]))
    ways, conditions = ways_of(folder, **options)
    asked = [(options["base"], p) for p in parts if p != options["base"]] if "base" in options else []
    orders, statement = necessary_orders(ways, conditions, asked)
    brute = BruteForce(parts, block, gravity="gravity" in options, connected="connected" in options,
                       base=options.get("base"))
    feasible = [seq for seq in itertools.permutations(brute.ids) if brute.feasible(seq)]
    for a, b in orders:
        assert all(seq.index(a) < seq.index(b) for seq in feasible), (a, b, orders[a, b])
    assert statement is None or not feasible, statement


def test_a_tilted_assembly_derives_as_on_the_axes(tmp_path):
    """One step off the axes: a voxel assembly turned by a random rotation.  The default directions (the
    axes and the contacts' normals) include the turned axes, and the plan admits exactly the sequences
    of the brute force on the unturned grid; the axes alone (now off every face) block more; gravity
    along the turned -z gives the brute force's count with gravity."""
    parts = partition((2, 2, 3), 5, seed=4)
    q, r = np.linalg.qr(np.random.default_rng(4).normal(size=(3, 3)))
    turn = q * np.sign(np.diag(r)) * (1 if np.linalg.det(q * np.sign(np.diag(r))) > 0 else -1)
    folder = write_assembly(tmp_path / "turned", parts)
    for f in folder.iterdir():
        lines = []
        for line in f.read_text().splitlines():
            if line.startswith("v "):
                line = "v " + " ".join(f"{c:.15g}" for c in turn @ np.array(line.split()[1:], float))
            lines.append(line)
        f.write_text("\n".join(lines) + "\n")
    derived = derive(folder)
    assert len(derived.blocking.directions) == 12          # six axes, six turned face normals
    assert Schedule(derived.plan).count() == BruteForce(parts, (2, 2, 3)).count()
    try:
        fewer = Schedule(derive(folder, directions="axes").plan).count()
    except DeriveError:
        fewer = 0
    assert fewer < Schedule(derived.plan).count()
    # gravity along the turned -z (a vector, not an axis): resting and the floor found off the axes too
    down = " ".join(f"{c:.15g}" for c in turn @ np.array([0, 0, -1.0]))
    held = derive(folder, gravity=down)
    assert Schedule(held.plan).count() == BruteForce(parts, (2, 2, 3), gravity=True).count() > 0


def test_too_many_contact_normals_are_refused_before_the_blocking(tmp_path, monkeypatch):
    """The default directions grow with the contacts' normals: over the limit, exit 1 saying to give
    --directions (checked before any blocking test); with --directions axes the same assembly derives."""
    from opportune.derive import blocking, directions

    folder = write_assembly(tmp_path / "wedge", {"a": [(0, 0, 0)]})
    # a wedge (a triangular prism, one face tilted) against the cube's +x face
    (folder / "b.obj").write_text("v 1 0 0\nv 1 1 0\nv 1 0 1\nv 1 1 1\nv 2 0 0\nv 2 1 0\n"
                                  "f 1 3 2\nf 2 3 4\nf 1 5 3\nf 2 4 6\nf 1 2 6\nf 1 6 5\nf 3 5 6\nf 3 6 4\n")
    assert len(derive(folder).blocking.directions) == 6            # the contact's normal is +x: an axis
    monkeypatch.setattr(directions, "MAX_DIRECTIONS", 5)
    called = []
    monkeypatch.setattr(blocking, "depth", lambda *a: called.append(1))
    r = run_cli("derive", folder)
    assert r.exit_code == 1 and "make 6 directions" in r.output and "give --directions" in r.output
    assert not called


def test_a_direction_blocked_by_the_only_support_is_no_way_in_the_ways_form():
    """b rests on a alone, and a is in b's way along -z: b goes in along +x only (a way whose need its
    blockers hold never admits the part, and a plan file refuses it; derive leaves it out)."""
    from opportune.derive.blocking import Blocking
    from opportune.derive.plan import Conditions
    from opportune.derive.ways import exact_ways
    from opportune.formats.loader import plan_from_dict

    free = {"-z": frozenset(), "+x": frozenset()}
    block = Blocking(("a", "b", "c"), {"-z": (0, 0, -1), "+x": (1, 0, 0)},
                     {"a": free, "b": {"-z": frozenset("a"), "+x": frozenset("c")}, "c": free}, 0, 0)
    ways = exact_ways(block, Conditions({"b": (("gravity", frozenset("a")),)}))
    assert [(w.name, w.blockers, w.needs) for w in ways["b"]] == [("+x", frozenset("c"), (frozenset("a"),))]
    from opportune.derive import plan_of

    plan = plan_of(block, [], "three", "listed", ways=ways)
    assert plan_from_dict(plan.to_dict()) == plan and Schedule(plan).count() == 1      # a, b, c
    with pytest.raises(DeriveError, match="every direction of b is blocked"):
        exact_ways(Blocking(("a", "b"), {"-z": (0, 0, -1)}, {"a": {"-z": frozenset()}, "b": {"-z": frozenset("a")}},
                            0, 0), Conditions({"b": (("gravity", frozenset("a")),)}))


# ---------------------------------------------------------------- derive --explain under the derivation's conditions


class HeldBruteForce(BruteForce):
    """The brute force with process constraints (``after``: part -> the parts before it) and some parts out of
    everyone's way (``gone``: no sweep meets them; they still hold and touch what rests on them)."""

    def __init__(self, parts, block, after=None, gone=(), **options):
        super().__init__(parts, block, **options)
        self.after = {self.ids.index(p): [self.ids.index(q) for q in qs] for p, qs in (after or {}).items()}
        mask = sum(1 << self.ids.index(q) for q in gone)
        self.swept = [[m & ~mask for m in masks] for masks in self.swept]

    def fits(self, i: int, built: int) -> bool:
        return all(built >> j & 1 for j in self.after.get(i, ())) and super().fits(i, built)


@pytest.mark.parametrize("seed", range(2))
def test_explain_recounts_under_the_supports_and_the_process_constraints(tmp_path, seed):
    """`derive --explain`'s "which part frees the most" derives each changed relation again under the
    derivation's own conditions: gravity, connected and a process constraint.  Each recount equals the
    brute force under the same conditions, and some differs from the brute force without them (what the
    recount gave when it dropped them)."""
    block = (3, 3, 2)
    parts = partition(block, 6, seed + 7)
    folder = write_assembly(tmp_path / "held", parts)
    supports = {"gravity": True, "connected": True}
    total = BruteForce(parts, block, **supports).count()
    # a process constraint that some feasible sequences keep and some do not
    after = next({b: [a]} for a, b in itertools.permutations(sorted(parts), 2)
                 if 0 < HeldBruteForce(parts, block, {b: [a]}, **supports).count() < total)
    derived = derive(folder, directions="axes", gravity="-z", connected=True, requires=after)
    e = explain(derived, time_limit=60)
    assert e.count["value"] == HeldBruteForce(parts, block, after, **supports).count()
    assert e.frees and not e.unfinished
    differs = 0
    for f in e.frees:
        held = HeldBruteForce(parts, block, after, gone=[f["name"]], **supports).count()
        assert f["count"]["exact"] and f["count"]["value"] == held, f
        differs += held != HeldBruteForce(parts, block, gone=[f["name"]]).count()
    assert differs


# ---------------------------------------------------------------- the convex pieces a plan carries for a body not convex


@pytest.mark.parametrize("seed", range(3))
def test_the_convex_pieces_of_a_body_not_convex_are_the_body(tmp_path, seed):
    """Random voxel parts written as one surface (not convex) are cut into convex pieces that fill them
    exactly: the pieces' hulls' volumes add up to the cells', each piece's centre is in a cell of the part,
    and no more pieces than cells."""
    from scipy.spatial import ConvexHull

    from opportune.derive.solids import convex_pieces

    found = 0
    for name, cells in partition((4, 4, 3), 6, seed).items():
        lines = surface_lines(cells)
        folder = tmp_path / name
        folder.mkdir()
        (folder / "p.obj").write_text("\n".join(lines or cube_lines(cells)) + "\n")
        body, = read_assembly(folder).parts[0].bodies if lines else (None,)
        if body is None or body.convex:
            continue
        found += 1
        pieces = convex_pieces(body, 64)
        assert pieces is not None and 2 <= len(pieces) <= len(cells)
        assert sum(ConvexHull(p).volume for p in pieces) == pytest.approx(len(cells), rel=1e-9)
        for p in pieces:
            centre = ConvexHull(p).points.mean(axis=0)
            assert tuple(int(c) for c in np.floor(centre)) in set(map(tuple, cells))
    assert found


def brute_facts(brute: BruteForce) -> tuple[dict, set]:
    """Each part's insertion directions and the forced orders, from the sets on some feasible sequence (reached
    from nothing, with a completion): a direction is one where a part goes in on such a set with its sweep
    clear, and ``a`` before ``b`` is forced where every such set holding ``b`` holds ``a``."""
    n = len(brute.ids)
    full = (1 << n) - 1

    @lru_cache(maxsize=None)
    def completes(built: int) -> bool:
        return built == full or any(completes(built | 1 << i) for i in range(n)
                                    if not built >> i & 1 and brute.fits(i, built))
    live, todo = {0}, [0]
    while todo:
        built = todo.pop()
        for i in range(n):
            nxt = built | 1 << i
            if not built >> i & 1 and brute.fits(i, built) and completes(nxt) and nxt not in live:
                live.add(nxt)
                todo.append(nxt)
    names = list(AXES)
    usable = {p: set() for p in brute.ids}
    for built in live:
        for i in range(n):
            if not built >> i & 1 and brute.fits(i, built) and built | 1 << i in live:
                usable[brute.ids[i]] |= {names[k] for k, m in enumerate(brute.swept[i]) if not m & built}
    forced = {(brute.ids[a], brute.ids[b]) for a in range(n) for b in range(n) if a != b
              and all(s >> a & 1 for s in live if s >> b & 1)}
    return usable, forced


@pytest.mark.parametrize("mode", sorted(MODES))
@settings(max_examples=8, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(block=st.sampled_from(BLOCKS), k=st.integers(2, 10), seed=st.integers(0, 2**32 - 1))
def test_what_explain_reads_from_the_ways_is_the_brute_forces(tmp_path_factory, mode, block, k, seed):
    """`derive --explain` on a plan written as ways: each part's insertion directions and the orders forced in
    every feasible sequence, read from the ways (sampled sequences, then peeling or a search), are the brute
    force's on the grid, under every support mode."""
    from opportune.derive.waysfacts import ways_facts

    k = min(k, block[0] * block[1] * block[2])
    parts = partition(block, k, seed)
    folder = write_assembly(tmp_path_factory.mktemp("voxels"), parts)
    options = dict(MODES[mode])
    if "base" in options:
        options["base"] = next(p for p, cells in parts.items() if (0, 0, 0) in cells)
    brute = BruteForce(parts, block, gravity="gravity" in options, connected="connected" in options,
                       base=options.get("base"))
    try:
        derived = derive(folder, directions="axes", form="ways", **options)
    except DeriveError:
        return
    facts = ways_facts(derived, seed=seed % 1000)
    usable, forced = brute_facts(brute)
    assert not facts.unfinished
    assert {p: set(d) for p, d in facts.usable.items()} == usable
    assert set(facts.forced) == forced
