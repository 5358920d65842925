"""The shipped assemblies, `derive --explain`, `derive --figure` and the shapes a derived plan carries to the
physical bin.

Counts are checked against an independent brute force: a dynamic programme over the sets of parts built,
where a part can go in after a set when some direction's blockers are all outside the set.
"""

from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

import pytest
from typer.testing import CliRunner

pytest.importorskip("trimesh")

from opportune.cli import app  # noqa: E402
from opportune.derive import derive  # noqa: E402
from opportune.derive import examples as ex  # noqa: E402
from opportune.derive.explain import Explanation, explain, printable, reasons  # noqa: E402
from opportune.engine import Schedule  # noqa: E402
from opportune.formats.shipped import GEOMETRY, geometry_path  # noqa: E402

runner = CliRunner()


@lru_cache(maxsize=None)
def derived(name: str):
    return derive(f"geometry:{name}")


@lru_cache(maxsize=None)
def held(gravity="-z", base=None):
    """The shipped gearbox derived under gravity (each part resting on one before it)."""
    return derive("geometry:gearbox", gravity=gravity, base=base)


@lru_cache(maxsize=None)
def explained(name: str):
    d = derived(name)
    return explain(d, d.assembly, time_limit=20)


def brute_count(parts, blockers) -> int:
    """Feasible sequences of a blocking relation: f(S) = sum over the parts p of S that can go in last
    (some direction's blockers all outside S - p) of f(S - p)."""
    index = {p: i for i, p in enumerate(parts)}
    masks = [[sum(1 << index[q] for q in qs) for qs in blockers[p].values()] for p in parts]
    f = [0] * (1 << len(parts))
    f[0] = 1
    for s in range(1, 1 << len(parts)):
        total = 0
        rest = s
        while rest:
            low = rest & -rest
            i = low.bit_length() - 1
            before = s & ~low
            if any(m & before == 0 for m in masks[i]):
                total += f[before]
            rest &= rest - 1
        f[s] = total
    return f[-1]


def test_the_shipped_meshes_are_the_scripts_output(tmp_path):
    for name in GEOMETRY:
        written = ex.write(name, tmp_path / name)
        shipped = sorted(geometry_path(name).iterdir())
        assert [p.name for p in shipped] == [p.name for p in written]
        assert all(a.read_bytes() == b.read_bytes() for a, b in zip(shipped, written)), name
        assert sum(p.stat().st_size for p in shipped) < 32_000      # small in the package
    looks = Path(str(geometry_path("gearbox").parent.parent / "gearbox-meshes.looks"))
    assert looks.read_text(encoding="utf-8") == ex.looks_text("gearbox", held().plan, options=" --gravity -z")


def test_the_gearbox_derives_and_counts_as_the_brute_force(tmp_path):
    out = tmp_path / "gearbox.yaml"
    result = runner.invoke(app, ["derive", "geometry:gearbox", "-o", str(out)])
    assert result.exit_code == 0, result.output
    counted = runner.invoke(app, ["count", str(out), "--json"])
    assert counted.exit_code == 0, counted.output
    d = derived("gearbox")
    doc = json.loads(counted.stdout)
    assert doc["exact"] and int(doc["sequences"]) == brute_count(d.blocking.parts, d.blocking.blockers) > 0


def test_the_gearbox_replays_its_looks(tmp_path):
    out = tmp_path / "gearbox.yaml"
    assert runner.invoke(app, ["derive", "geometry:gearbox", "--gravity", "-z", "-o", str(out)]).exit_code == 0
    replayed = runner.invoke(app, ["replay", str(out), "example:gearbox-meshes", "--json"])
    assert replayed.exit_code == 0, replayed.output
    steps = json.loads(replayed.stdout)
    assert steps[-1]["action"]["kind"] == "done"
    assert sorted(steps[-1]["installed"]) == sorted(derived("gearbox").blocking.parts)


def test_the_plan_carries_each_parts_shape_and_the_physical_bin_heaps_them(tmp_path):
    pytest.importorskip("mujoco")
    from opportune.formats.loader import load_plan
    from opportune.study.simulate import StudyConfig, run_study
    from opportune.worlds.physics import PhysicsBin

    out = tmp_path / "gearbox.yaml"
    assert runner.invoke(app, ["derive", "geometry:gearbox", "-o", str(out)]).exit_code == 0
    plan = load_plan(out)
    d = derived("gearbox")
    import numpy as np

    for part in d.assembly.parts:        # every body of every part, as its corners (to a micrometre)
        shape, bodies = next(p for p in plan.parts if p.id == part.id).geometry
        assert shape == "convex" and len(bodies) == len(part.bodies)
        for body, written in zip(part.bodies, bodies):
            assert np.abs(body.vertices - np.array(written)).max() <= 1e-6
    geometry = {p.id: p.geometry for p in plan.parts}
    world = PhysicsBin(visible=2, geometry=geometry)
    import random

    world.reset([p.id for p in plan.parts], random.Random(3))
    import mujoco

    meshes = sum(1 for g in range(world.model.ngeom) if world.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH)
    assert meshes == sum(len(p.bodies) for p in d.assembly.parts)
    exposure = world.exposure()                  # rays over each real shape: some seen whole, some hidden
    assert max(exposure.values()) > 0.9 and min(exposure.values()) < 0.9 and world.look()
    alone = PhysicsBin(visible=1, geometry=geometry)
    alone.reset(["gear_a"], random.Random(1))    # a gear alone in the bin: in full view, pickable
    assert alone.exposure() == {0: 1.0} and alone.look() == ("gear_a",)
    result = run_study(StudyConfig(plan, strategies=("paper",), trials=1, bin="physics", seed=2), workers=1)
    trial, = result.trials["paper"]
    assert trial.complete and trial.motions >= len(plan.parts)        # every part picked from the heap


def held_count(parts, blockers, needs) -> int:
    """Feasible sequences with supports, forward over the reachable built sets: a part goes in after a set
    when each of its supports has a part in the set and some direction's blockers are all outside it."""
    index = {p: i for i, p in enumerate(parts)}
    masks = [[sum(1 << index[q] for q in qs) for qs in blockers[p].values()] for p in parts]
    held = [[sum(1 << index[q] for q in n) for _, n in needs.get(p, ())] for p in parts]
    layer = {0: 1}
    for _ in parts:
        grown: dict[int, int] = {}
        for built, ways in layer.items():
            for i in range(len(parts)):
                if not built >> i & 1 and all(h & built for h in held[i]) and any(m & built == 0 for m in masks[i]):
                    grown[built | 1 << i] = grown.get(built | 1 << i, 0) + ways
        layer = grown
    return sum(layer.values())


def test_the_gearbox_derives_under_gravity_and_its_sequences_replay(tmp_path):
    """Under --gravity -z (and with the housing as the base) every part rests on one placed before it: the
    plan's count is the brute force's with the supports, every sampled sequence is feasible (each part
    held and with a free direction when it goes in), and replays part by part to the end."""
    out = tmp_path / "gearbox.yaml"
    for extra in ([], ["--base", "housing"]):
        result = runner.invoke(app, ["derive", "geometry:gearbox", "--gravity", "-z", *extra, "-o", str(out)])
        assert result.exit_code == 0, result.output
    d = held()
    b, needs = d.blocking, d.conditions.needs
    assert set(needs) == set(b.parts) - {"housing"}          # all but the housing rest on a part
    assert Schedule(d.plan).count() == held_count(b.parts, b.blockers, needs) > 0
    assert Schedule(held(base="housing").plan).count() == Schedule(d.plan).count()   # the housing is first anyway
    for k in range(40):
        seq = Schedule(d.plan).sample(seed=k)
        for n, p in enumerate(seq):
            built = set(seq[:n])
            assert all(s & built for _, s in needs.get(p, ())), (seq, p)
            assert any(not (q & built) for q in b.blockers[p].values()), (seq, p)
        if k < 4:                        # the camera shows the parts one at a time, in this order
            looks = tmp_path / f"seq{k}.looks"
            looks.write_text("\n".join(seq) + "\n", encoding="utf-8")
            replayed = runner.invoke(app, ["replay", str(out), str(looks), "--json"])
            steps = json.loads(replayed.stdout)
            assert steps[-1]["action"]["kind"] == "done" and steps[-1]["installed"] == list(seq), replayed.stdout


def test_explain_under_gravity_keeps_the_supports():
    """Insertion directions and recounts under the supports: a direction is one iff the brute force with the
    part held to it finds a sequence; each part out of everyone's way is recounted with the supports kept."""
    d = held()
    e = explain(d, time_limit=20)
    b, needs = d.blocking, d.conditions.needs
    assert e.count["value"] == held_count(b.parts, b.blockers, needs)
    for p in b.parts:
        for k in b.directions:
            one = {**b.blockers, p: {k: b.blockers[p][k]}}
            assert (k in e.usable[p]) == (held_count(b.parts, one, needs) > 0), (p, k)
    assert e.usable["gear_a"] == ["-x"] and e.usable["bearing_a1"] == ["+x"]     # slid onto its shaft; from outside
    assert "gear_a after shaft_a: resting on shaft_a" in e.text()      # a support, said as gravity's
    for f in e.frees:
        out = {p: {k: s - {f["name"]} for k, s in dirs.items()} for p, dirs in b.blockers.items()}
        assert f["count"]["exact"] and f["count"]["value"] == held_count(b.parts, out, needs), f


def test_explain_states_only_what_the_blocking_relation_says():
    d = derived("gearbox")
    e = explained("gearbox")
    b = d.blocking.blockers
    constraints = [c for order in e.orders for c in order["constraints"]]
    assert constraints
    for c in constraints:     # the later part really is in the earlier one's way along its direction
        assert c["after"] in b[c["before"]][c["direction"]]
        assert c["other_directions"] == {k: sorted(q) for k, q in b[c["before"]].items() if k != c["direction"]}
    for r in reasons(e):
        assert set(r["before"]) <= b[r["part"]][r["direction"]]
    # every pair the plan forces in all its strategies is an order of every feasible sequence: its
    # reverse is infeasible (the brute force with the later part forced first finds none)
    text = e.text()
    assert "forced orders:" in text and "frees the most:" in text
    # the report's count is the brute force's
    assert e.count["exact"] and e.count["value"] == brute_count(d.blocking.parts, b)


def test_what_frees_the_most_is_checked_by_recounting():
    d = derived("pump")
    e = explained("pump")
    b = d.blocking.blockers
    parts = d.blocking.parts
    recount = {}
    for q in parts:
        recount[q] = brute_count(parts, {p: {k: s - {q} for k, s in dirs.items()} for p, dirs in b.items()})
    from opportune.derive.blocking import find_blocking

    for f in e.frees:
        if f["kind"] == "direction":    # an added direction, found in the geometry again and counted
            extra = find_blocking(d.assembly, {f["name"]: ex_direction(f["name"])})
            recount[f["name"]] = brute_count(parts, {p: {**dirs, f["name"]: extra.blockers[p][f["name"]]}
                                                     for p, dirs in b.items()})
        c = f["count"]
        if c["exact"]:                # each recount is the brute force's, or an estimate whose interval holds it
            assert c["value"] == recount[f["name"]], f
        else:
            assert c["log10_low"] - 1e-9 <= math.log10(recount[f["name"]]) <= c["log10_high"] + 1e-9, f
    blocking = {q for q in parts if any(q in s for x in b.values() for s in x.values())}
    tried = {f["name"] for f in e.frees if f["kind"] == "part"}
    assert tried == blocking or (e.unfinished and tried < blocking)     # every part in someone's way, in time
    best = e.frees[0]
    assert recount[best["name"]] == max(recount[f["name"]] for f in e.frees)     # it does free the most
    assert f"frees the most: {best['name']} out of everyone's way" in e.text()


def ex_direction(name: str):
    from opportune.derive.explain import DIAGONALS

    return DIAGONALS[name]


def test_insertion_directions_are_those_of_some_feasible_sequence():
    d = derived("pump")
    e = explained("pump")
    b = d.blocking.blockers
    for p in d.blocking.parts:
        for k in d.blocking.directions:
            held = {**b, p: {k: b[p][k]}}
            assert (k in e.usable[p]) == (brute_count(d.blocking.parts, held) > 0), (p, k)


def test_explain_text_and_json_from_the_command_line():
    result = runner.invoke(app, ["derive", "geometry:pump", "--explain"])
    assert result.exit_code == 0, result.output
    assert "frees the most:" in result.stdout and "one insertion direction only" in result.stdout
    as_json = runner.invoke(app, ["derive", "geometry:pump", "--explain", "--json"])
    doc = json.loads(as_json.stdout)
    assert doc["explanation"]["count"]["value"] == Schedule(derived("pump").plan).count()
    assert doc["explanation"]["reasons"]


def test_explain_text_escapes_control_characters():
    e = Explanation("bad\x1b[2Jname", ("a\x07",), [], {"a\x07": ["+x"]},
                    {"value": 1, "exact": True, "log10": 0.0, "log10_all_orders": 0.0, "share_log10": 0.0}, [])
    text = e.text()
    assert "\x1b" not in text and "\x07" not in text and "\\x1b[2J" in text
    assert printable("a\udcff") == "a\\udcff"


@pytest.mark.parametrize("suffix", [".png", ".svg"])
def test_the_exploded_view_is_drawn(tmp_path, suffix):
    out = tmp_path / f"gearbox{suffix}"
    result = runner.invoke(app, ["derive", "geometry:gearbox", "--figure", str(out), "-o", str(tmp_path / "p.yaml")])
    assert result.exit_code == 0, result.output
    if suffix == ".svg":
        text = out.read_text(encoding="utf-8")
        assert all(p in text for p in derived("gearbox").blocking.parts)    # every part labelled
        assert text.count("<path") > 200                                    # the faces drawn
    else:
        from matplotlib.image import imread

        pixels = imread(out)
        assert pixels.shape[0] > 800 and pixels.shape[1] > 1000             # print size at 200 dpi
        assert pixels[..., :3].std() > 0.1                                  # not a blank page


def test_a_figure_that_cannot_be_drawn_is_refused_before_anything_is_written(tmp_path):
    plan = tmp_path / "p.yaml"
    bad = runner.invoke(app, ["derive", "geometry:gearbox", "--figure", str(tmp_path / "x.gif"), "-o", str(plan)])
    assert bad.exit_code == 1 and "x.gif" in bad.output and not plan.exists()
    nowhere = runner.invoke(app, ["derive", "geometry:pump", "--figure", str(tmp_path / "no" / "x.svg"), "-o", str(plan)])
    assert nowhere.exit_code == 1 and "cannot write the figure" in nowhere.output and not plan.exists()
    many = runner.invoke(app, ["derive", "geometry:gearbox", "--figure", str(tmp_path / "x.png"), "--strategy", "99"])
    assert many.exit_code == 1 and "strategy 99" in many.output


def test_the_puzzle_is_refused_naming_the_parts_that_lock():
    result = runner.invoke(app, ["derive", "geometry:puzzle"])
    assert result.exit_code == 1
    assert "link_a" in result.output and "link_b" in result.output and "stand" not in result.output
    unknown = runner.invoke(app, ["derive", "geometry:nothing"])
    assert unknown.exit_code == 1 and "gearbox, pump, puzzle" in unknown.output


def test_parts_outside_the_shapes_bounds_are_written_without_one_and_said(tmp_path):
    for part, bodies in ex.gearbox().items():        # the gearbox ten times larger: housing, cover, shafts 0.8 m
        (tmp_path / f"{part}.obj").write_text(ex.obj_text([(c * 10, f) for c, f in bodies]), encoding="utf-8")
    d = derive(tmp_path)
    without = {p.id for p in d.plan.parts if p.geometry is None}
    assert without == {"housing", "cover", "shaft_a", "shaft_b"}
    assert all(any(f"'{p}'" in n for n in d.notes) for p in without)
    result = runner.invoke(app, ["derive", str(tmp_path), "-o", str(tmp_path / "p.yaml")])
    assert result.exit_code == 0 and "housing" in result.output and "default box" in result.output


def test_a_part_id_with_dollars_is_drawn_as_written_not_as_mathtext(tmp_path):
    for part, bodies in ex.puzzle().items():
        if part != "link_b":     # the stand and one link: nothing locked
            (tmp_path / f"{part.replace('link_a', 'a$b$c')}.obj").write_text(ex.obj_text(bodies), encoding="utf-8")
    out = tmp_path / "x.svg"
    result = runner.invoke(app, ["derive", str(tmp_path), "--figure", str(out), "--explain"])
    assert result.exit_code == 0, result.output
    assert "a$b$c" in out.read_text(encoding="utf-8") and "1 in 10^0.00" in result.stdout


def test_a_part_that_is_not_convex_is_heaped_as_its_convex_pieces_and_holds_a_peg_in_its_slot(tmp_path):
    """A U written as one closed surface (not convex) is carried as convex pieces whose union is the U, none
    over its slot; in the physical bin, the U and a peg placed in its slot as assembled touch without
    MuJoCo finding them overlapping (its convex hull, the old shape, swallows the peg)."""
    pytest.importorskip("mujoco")
    import mujoco
    import numpy as np
    from scipy.spatial import Delaunay

    from opportune.worlds.physics import PhysicsBin
    from test_derive import cube_lines, surface_lines

    cell = 0.02
    u_cells = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 0, 1), (2, 0, 1)]

    def scaled(lines):
        return "\n".join("v " + " ".join(str(cell * float(c)) for c in line.split()[1:]) if line.startswith("v ")
                         else line for line in lines) + "\n"

    (tmp_path / "u.obj").write_text(scaled(surface_lines(u_cells)))
    (tmp_path / "peg.obj").write_text(scaled(cube_lines([(1, 0, 1)])))
    d = derive(tmp_path, directions="axes")
    u = next(p for p in d.assembly.parts if p.id == "u")
    assert len(u.bodies) == 1 and not u.bodies[0].convex and not d.notes
    geometry = {p.id: p.geometry for p in d.plan.parts}
    shape, pieces = geometry["u"]
    assert shape == "convex" and 2 <= len(pieces) <= 5
    slot = np.array([1.5, 0.5, 1.5]) * cell
    volume = 0.0
    for piece in pieces:
        hull = Delaunay(np.array(piece))
        assert hull.find_simplex(slot) < 0                    # no piece reaches into the slot
        volume += sum(abs(np.linalg.det(hull.points[s[1:]] - hull.points[s[0]])) / 6 for s in hull.simplices)
    assert volume == pytest.approx(len(u_cells) * cell ** 3, rel=1e-6)
    bounds = {p.id: p.bounds for p in d.assembly.parts}

    def deepest(geometry, sink=0.0):
        """The deepest overlap MuJoCo finds between the U and the peg placed as assembled (the peg lowered by
        ``sink``), 0 if none; and the U's geoms."""
        world = PhysicsBin(visible=2, geometry=geometry)
        world._build(["u", "peg"])
        for i, part in enumerate(("u", "peg")):          # both as assembled, lifted into the bin's air
            lo, hi = bounds[part]
            adr = world._qadr[i]
            world.data.qpos[adr:adr + 7] = [*((lo + hi) / 2 + [0, 0, 0.1 - (sink if i else 0)]), 1, 0, 0, 0]
        mujoco.mj_forward(world.model, world.data)
        peg = set(world._geoms[1])
        pairs = [(c.dist, {int(c.geom1), int(c.geom2)}) for c in world.data.contact[:world.data.ncon]]
        return min([dist for dist, g in pairs if g & peg and g - peg] + [0.0]), world._geoms[0]

    depth, geoms = deepest(geometry)
    assert len(geoms) == len(pieces) and depth > -1e-3 * cell          # in the slot, touching, not overlapping
    assert deepest(geometry, sink=0.2 * cell)[0] < -0.1 * cell         # pushed into the U's floor: found
    hull = {**geometry, "u": ("convex", [[c for body in pieces for c in body]])}
    assert deepest(hull)[0] < -0.3 * cell                               # the U as one hull swallows the peg


def test_the_pump_derives_under_gravity_every_part_resting_on_one_below():
    """The pump under --gravity -z: the housing on the fixture, the seal on the lip of its stepped bore, the
    bearing on the seal (its flange on the floor), the shaft's collar on the bearing, the impeller and the key
    on the collar, the cover on the housing, the bolts in their holes; the count is the brute force's with
    the supports."""
    d = derive("geometry:pump", gravity="-z")
    b, needs = d.blocking, d.conditions.needs
    assert set(needs) == set(b.parts) - {"housing"}
    on = {p: set().union(*(n for _, n in needs[p])) for p in needs}
    assert on["seal"] == {"housing"} and on["bearing"] == {"seal", "housing"} and on["shaft"] == {"bearing"}
    assert on["impeller"] >= {"shaft"} and on["key"] >= {"shaft"} and "housing" in on["cover"]
    assert Schedule(d.plan).count() == held_count(b.parts, b.blockers, needs) == 48


def facts(e) -> tuple:
    """What an explanation says of the plan, whatever its form."""
    doc = e.to_dict()
    return e.usable, doc["single_direction"], e.forced, e.count["value"], e.count["exact"]


@pytest.mark.parametrize("name, gravity", [("pump", "-z"), ("gearbox", "-z"), ("pump", None)])
def test_explain_reads_the_same_facts_from_the_plan_written_as_ways(name, gravity):
    """Derived as strategies and as ways, the explanation's facts agree: each part's insertion directions,
    the parts with one, the orders forced in every feasible sequence and the count.  Each forced order of the
    ways form says the directions along which the later part blocks the earlier one (it does, in the
    blocking relation) and the other directions' blockers, or the support."""
    strategies = derive(f"geometry:{name}", gravity=gravity)
    ways = derive(f"geometry:{name}", gravity=gravity, form="ways")
    assert ways.plan.is_ways and not strategies.plan.is_ways
    es, ew = explain(strategies, time_limit=60), explain(ways, time_limit=60)     # (time for a loaded machine)
    assert facts(ew) == facts(es)
    assert not [u for u in es.unfinished + ew.unfinished if "directions of" in u or "orders" in u]
    b = ways.blocking.blockers
    closed = set(ew.forced)
    for c in ew.orders[0]["constraints"]:
        assert (c["before"], c["after"]) in closed
        if c["direction"]:
            assert all(c["after"] in b[c["before"]][d] for d in c["direction"].split(", "))
            assert all(c["after"] not in b[c["before"]][d] for d in c["other_directions"])
        else:
            assert c["support"] and any(c["before"] in n for _, n in ways.conditions.needs[c["after"]])
    text = ew.text()
    assert text.startswith(f"{name}: {len(b)} parts, written as each part's ways in")
    assert "forced in every feasible sequence" in text and "frees the most:" in text
    assert ew.to_dict()["form"] == "ways"


def test_the_exploded_view_of_a_plan_written_as_ways_draws_one_feasible_sequence(tmp_path):
    """The figure of a plan written as ways: one feasible sequence read as a strategy, whose every linear
    extension the plan admits (each part before the parts in its way along its direction, after a support)."""
    from opportune.derive.figure import levels
    from opportune.derive.waysfacts import sequence_strategy

    d = derive("geometry:gearbox", gravity="-z", form="ways")
    s = sequence_strategy(d)
    level, _ = levels(d.blocking.parts, s.pairs)
    for order in (sorted(d.blocking.parts, key=lambda p: level[p]),
                  sorted(d.blocking.parts, key=lambda p: (level[p], p[::-1]))):
        schedule = Schedule(d.plan)
        for p in order:
            assert p in schedule.installable(), (order, p)
            schedule = schedule.install(p)
    from opportune.derive.figure import exploded

    out = exploded(d, tmp_path / "ways.svg")
    text = out.read_text(encoding="utf-8")
    assert "one feasible sequence" in text and all(p in text for p in d.blocking.parts)
    with pytest.raises(ValueError, match="draws one feasible sequence"):
        exploded(d, out, strategy=2)
