"""Rational relaxation (issue 15, part 3): the cheapest set of constraints to drop, against brute force.

The feedback arc set is compared with an exhaustive search (over vertex orders, and over arc subsets
for whole plans with an installed prefix); the two exact methods are compared with each other on
larger graphs; the command line's relaxed plan is checked and replayed; weights parse, round-trip and
are refused with their place when bad; hostile plans are refused or answered within their limit.
"""

from __future__ import annotations

import itertools
import json
import pickle

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import CpuTime, run_cli
from opportune.derive.relax import (MAX_COMPONENT_ARCS, RelaxRefused, RelaxTimeout, min_feedback_arc_set,
                                    prefix_violations, relax)
from opportune.formats.loader import check_text, read_plan
from opportune.planning.plan import Plan, Strategy

OVER = "example:gearbox-overconstrained"


# ---------------------------------------------------------------- brute force


def acyclic(nodes, arcs) -> bool:
    """Kahn's algorithm, written again here (not the module's)."""
    indeg = {v: 0 for v in nodes}
    for _, v in arcs:
        indeg[v] += 1
    ready = [v for v, d in indeg.items() if d == 0]
    seen = 0
    while ready:
        u = ready.pop()
        seen += 1
        for a, b in arcs:
            if a == u:
                indeg[b] -= 1
                if indeg[b] == 0:
                    ready.append(b)
    return seen == len(indeg)


def brute_by_orders(nodes, arcs: dict) -> float:
    """The least weight of the arcs pointing backwards in some order of the vertices."""
    best = float("inf")
    for order in itertools.permutations(nodes):
        pos = {v: i for i, v in enumerate(order)}
        best = min(best, sum(w for (u, v), w in arcs.items() if pos[v] < pos[u]))
    return best


@st.composite
def weighted_digraphs(draw, min_n=1, max_n=7, max_p=1.0):
    """``(n, {(u, v): weight})``: each arc present with probability p (drawn), weights 1 to 9, from a seed
    (hypothesis would otherwise favour the empty and the complete graph)."""
    import random

    n = draw(st.integers(min_n, max_n))
    p = draw(st.floats(0.1, max_p))
    rng = random.Random(draw(st.integers(0, 2**32)))
    return n, {(u, v): rng.randint(1, 9) for u in range(n) for v in range(n) if u != v and rng.random() < p}


# ---------------------------------------------------------------- the feedback arc set


@settings(max_examples=150, deadline=None)
@given(weighted_digraphs())
def test_feedback_arc_set_is_minimal_by_exhaustive_search(graph):
    n, arcs = graph
    best = brute_by_orders(range(n), arcs)
    for method in ("dp", "bb"):
        weight, dropped = min_feedback_arc_set(range(n), arcs, method=method)
        assert weight == best, (method, arcs)
        assert weight == sum(arcs[a] for a in dropped)
        assert acyclic(range(n), [a for a in arcs if a not in set(dropped)])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 5).flatmap(lambda n: st.tuples(st.just(n), st.dictionaries(
    st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)).filter(lambda a: a[0] != a[1]),
    st.integers(1, 4), max_size=9))))
def test_feedback_arc_set_is_minimal_over_all_arc_subsets(graph):
    """The definition itself: the cheapest subset of arcs whose removal leaves no cycle."""
    n, arcs = graph
    keys = list(arcs)
    best = min(sum(arcs[a] for a in sub) for k in range(len(keys) + 1) for sub in itertools.combinations(keys, k)
               if acyclic(range(n), [a for a in keys if a not in sub]))
    assert min_feedback_arc_set(range(n), arcs)[0] == best


@settings(max_examples=25, deadline=None)
@given(weighted_digraphs(min_n=8, max_n=14, max_p=0.35))
def test_branch_and_bound_agrees_with_the_subset_dp(graph):
    n, arcs = graph
    w_dp, cut_dp = min_feedback_arc_set(range(n), arcs, method="dp")
    w_bb, cut_bb = min_feedback_arc_set(range(n), arcs, method="bb", time_limit=30)
    assert w_bb == w_dp
    assert acyclic(range(n), [a for a in arcs if a not in set(cut_bb)])


def test_feedback_arc_set_edge_cases():
    assert min_feedback_arc_set([], {}) == (0.0, [])
    assert min_feedback_arc_set("ab", {("a", "a"): 2, ("a", "b"): 1}) == (2.0, [("a", "a")])
    # parallel arcs add their weights: dropping b -> a (1 + 1) costs as much as dropping a -> b (2)
    weight, cut = min_feedback_arc_set("ab", [("a", "b", 3), ("b", "a", 1), ("b", "a", 1)])
    assert weight == 2.0 and cut == [("b", "a")]
    # arcs between components lie on no cycle and are never dropped, however light
    arcs = {("a", "b"): 5, ("b", "a"): 5, ("b", "c"): 0.001, ("c", "d"): 1, ("d", "c"): 2}
    assert min_feedback_arc_set("abcd", arcs) == (6.0, [("a", "b"), ("c", "d")])
    for bad in (0, -1, float("nan"), float("inf"), "2", True):
        with pytest.raises(ValueError, match="weight"):
            min_feedback_arc_set("ab", {("a", "b"): bad})


# ---------------------------------------------------------------- relaxing plans


def tiny_plan(n, arcs: dict, extra_strategies=()) -> Plan:
    """A plan straight from arcs (cycles allowed, as ``read_plan(..., allow_cycles=True)`` gives)."""
    from opportune.planning.plan import Part

    def strategy(name, arcs):
        req: dict = {}
        for u, v in arcs:
            req.setdefault(f"p{v}", []).append(f"p{u}")
        return Strategy(name, req, {(f"p{u}", f"p{v}"): w for (u, v), w in arcs.items()})

    strategies = [strategy("s0", arcs)] + [strategy(f"s{i + 1}", a) for i, a in enumerate(extra_strategies)]
    return Plan("tiny", tuple(Part(f"p{i}") for i in range(n)), tuple(strategies))


def admits(plan: Plan, prefix) -> bool:
    from opportune.engine import NotAdmissible, Schedule

    sched = Schedule(plan)
    try:
        for p in prefix:
            sched = sched.install(p)
    except NotAdmissible:
        return False
    return sched.count() > 0


def is_valid(plan: Plan) -> bool:
    from opportune.formats.loader import Document
    from opportune.formats.validate import check_document

    return check_document(Document(plan.to_dict())).ok


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 5).flatmap(lambda n: st.tuples(st.just(n), st.dictionaries(
    st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)).filter(lambda a: a[0] != a[1]),
    st.integers(1, 4), max_size=10))), st.data())
def test_relaxing_a_plan_with_a_prefix_is_minimal_over_all_arc_subsets(graph, data):
    n, arcs = graph
    plan = tiny_plan(n, arcs)
    prefix = [f"p{i}" for i in data.draw(st.permutations(range(n)))][:data.draw(st.integers(0, n))]
    result = relax(plan, prefix)
    keys = list(arcs)
    names = [f"p{i}" for i in range(n)]

    def fixes(sub) -> bool:
        kept = [a for a in keys if a not in sub]
        if not acyclic(range(n), kept):
            return False
        pos = {p: i for i, p in enumerate(prefix)}
        # every constraint into an installed part comes from a part installed before it
        return all(f"p{v}" not in pos or (f"p{u}" in pos and pos[f"p{u}"] < pos[f"p{v}"]) for u, v in kept)

    best = min(sum(arcs[a] for a in sub) for k in range(len(keys) + 1)
               for sub in itertools.combinations(keys, k) if fixes(sub))
    assert result.minimal and result.weight == best
    assert is_valid(result.plan) and admits(result.plan, prefix)
    assert set(result.plan.part_ids) == set(names)
    kept = {(b, a) for s in result.plan.strategies for b, a in s.pairs()}
    dropped = {(d.before, d.after) for d in result.dropped}
    assert kept | dropped == {(f"p{u}", f"p{v}") for u, v in keys} and not kept & dropped
    assert all(d.forced == ((d.before, d.after) in set(prefix_violations(plan, plan.strategies[0], prefix)))
               for d in result.dropped)


def test_the_cheapest_strategy_is_repaired_for_the_prefix_and_the_others_kept():
    # s0 contradicts the prefix p1 p0 at weight 5, s1 at weight 2 (and has a cycle costing 1 anyway)
    plan = tiny_plan(3, {(0, 1): 5, (1, 2): 1}, extra_strategies=[{(0, 1): 2, (1, 2): 1, (2, 1): 1}])
    result = relax(plan, ["p1", "p0"])
    assert result.repaired == "s1" and result.minimal
    assert {(d.strategy, d.before, d.after, d.forced) for d in result.dropped} == {
        ("s1", "p0", "p1", True), ("s1", "p2", "p1", True)}
    assert result.weight == 3.0
    assert [s.name for s in result.plan.strategies] == ["s0", "s1"] and is_valid(result.plan)
    assert admits(result.plan, ["p1", "p0"])
    # a strategy already admits the prefix: only the cycle of s1 is cut
    again = relax(plan, ["p0"])
    assert again.repaired is None and [(d.strategy, d.weight, d.forced) for d in again.dropped] == [("s1", 1.0, False)]


def test_strategies_that_become_the_same_are_merged():
    plan = tiny_plan(3, {(0, 1): 1, (1, 0): 1}, extra_strategies=[{(1, 0): 3, (0, 1): 2}])
    result = relax(plan)
    # s0 drops one of its weight-1 arcs; s1 drops p0 -> p1 (2) and keeps p1 -> p0, as s0 does
    assert [s.name for s in result.plan.strategies] == ["s0"]
    assert result.removed == (("s1", "s0"),)
    assert is_valid(result.plan) and result.weight == 3.0


def test_an_admissible_plan_is_left_as_it_is():
    plan = read_plan("example:gearbox").plan
    result = relax(plan, ["ca", "ba"])
    assert not result.changed and result.weight == 0 and result.minimal and result.plan == plan


def test_a_bad_prefix_is_refused_by_name():
    plan = read_plan(OVER, allow_cycles=True).plan
    with pytest.raises(ValueError, match="unknown part 'zz'"):
        relax(plan, ["ca", "zz"])
    with pytest.raises(ValueError, match="installed 2 times"):
        relax(plan, ["ca", "ca"])


# ---------------------------------------------------------------- weights in plan files


def test_weights_parse_and_round_trip():
    text = "parts: [a, b, c]\nrequires:\n  c: [a, {part: b, weight: 5}]\n  b: {part: a, weight: 2.5}\n"
    result = check_text(text, file="w.yaml")
    assert result.ok, result.problems
    s = result.plan.strategies[0]
    assert s.requires == {"c": ("a", "b"), "b": ("a",)}
    assert s.weight("b", "c") == 5 and s.weight("a", "b") == 2.5 and s.weight("a", "c") == 1
    doc = result.plan.to_dict()
    assert doc["strategies"][0]["requires"] == {"c": ["a", {"part": "b", "weight": 5}],
                                                "b": [{"part": "a", "weight": 2.5}]}
    again = check_text(json.dumps(doc), fmt="json").plan
    assert again.strategies == result.plan.strategies
    assert pickle.loads(pickle.dumps(result.plan)).strategies == result.plan.strategies
    assert hash(again.strategies[0]) == hash(s)
    # weight 1 written out is the default: the same strategy as a plain id
    plain = check_text("parts: [a, b]\nrequires: {b: [{part: a, weight: 1}]}\n").plan.strategies[0]
    assert plain == Strategy("default", {"b": ("a",)}) and plain.weights == {}
    assert Strategy("x", {"b": ("a",)}, {("a", "b"): 2}) != Strategy("x", {"b": ("a",)})


@pytest.mark.parametrize("bad, says", [("-1", "must be > 0"), ("0", "must be > 0"), ("'heavy'", "expected number"),
                                       (".nan", "not a finite number"), ("1.0e+12", "at most 1,000,000"),
                                       ("[1]", "expected number")])
def test_bad_weights_are_refused_with_their_line(bad, says):
    text = f"parts: [a, b, c]\nrequires:\n  c: [a]\n  b:\n    - {{part: a, weight: {bad}}}\n"
    result = check_text(text, file="w.yaml")
    assert not result.ok
    (problem,) = result.errors
    assert says in problem.message and problem.line == 5 and problem.file == "w.yaml", problem


def test_an_unknown_field_in_a_weighted_entry_is_named():
    result = check_text("parts: [a, b]\nrequires:\n  b: [{part: a, wieght: 2}]\n", file="w.yaml")
    assert not result.ok and "did you mean `weight`" in str(result.errors[0]) and result.errors[0].line == 3


# ---------------------------------------------------------------- the command line


def test_check_points_to_relax_and_relax_repairs_the_example(tmp_path):
    checked = run_cli("check", OVER)
    assert checked.exit_code == 1 and "opportune relax" in checked.stdout
    result = run_cli("relax", OVER)
    assert result.exit_code == 0, result.output
    out = tmp_path / "relaxed.yaml"
    out.write_text(result.stdout)
    assert run_cli("check", out).exit_code == 0
    assert "dropped 2 constraints of total weight 2 (minimal)" in result.stderr
    assert "cl -> ba" in result.stderr and "ml -> co" in result.stderr
    assert f"{OVER}:16" in result.stderr            # the line of `ba: [ca, cl]`
    relaxed = read_plan(out).plan
    assert relaxed.strategies[0].weight("st", "ml") == 5      # weights kept for the constraints kept
    assert run_cli("count", out).exit_code == 0


def test_relax_json_output_file_and_installed(tmp_path):
    out = tmp_path / "r.yaml"
    result = run_cli("relax", OVER, "--installed", "ca,ba,sm,dr,co", "-o", out, "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["minimal"] is True and doc["weight"] == 4
    assert {(d["before"], d["after"]) for d in doc["dropped"]} == {("cl", "ba"), ("rl", "co"), ("ml", "co"),
                                                                   ("ra", "co")}
    assert all(d["forced"] for d in doc["dropped"])
    relaxed = read_plan(out).plan
    assert relaxed.to_dict() == doc["plan"] | {"name": relaxed.name}
    assert admits(relaxed, ["ca", "ba", "sm", "dr", "co"])


def test_relax_of_an_admissible_plan_says_so_and_writes_it_unchanged():
    result = run_cli("relax", "example:gearbox")
    assert result.exit_code == 0 and "already admissible" in result.stderr
    assert check_text(result.stdout).plan.strategies == read_plan("example:gearbox").plan.strategies
    doc = json.loads(run_cli("relax", "example:gearbox", "--json").stdout)
    assert doc["dropped"] == [] and doc["weight"] == 0 and doc["minimal"] is True


def test_relax_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("parts: [a, b]\nrequires:\n  b: [a, zz]\n")
    result = run_cli("relax", bad)
    assert result.exit_code == 1 and "bad.yaml:3" in result.stderr and "unknown part 'zz'" in result.stderr
    result = run_cli("relax", OVER, "--installed", "ca qq")
    assert result.exit_code == 1 and "unknown part 'qq'" in result.stderr
    result = run_cli("relax", OVER, "--installed", "ca qq", "--json")
    assert result.exit_code == 1 and "unknown part 'qq'" in json.loads(result.stdout)["error"]["message"]
    result = run_cli("relax", tmp_path / "missing.yaml")
    assert result.exit_code == 1 and "no such file" in result.stderr
    in2 = tmp_path / "cyclic.IN2"   # a format read only when acyclic: say what to do instead
    in2.write_text("3\n1\n1\n1\n1,2\n2,3\n3,1\n-1,-1\n")
    result = run_cli("relax", in2)
    assert result.exit_code == 1 and "from YAML and JSON files only" in result.stderr


# ---------------------------------------------------------------- hostile plans


def test_a_dense_200_part_cyclic_plan_is_refused_quickly(tmp_path):
    n = 200
    lines = [f"parts: [{', '.join(f'p{i}' for i in range(n))}]", "requires:"]
    for v in range(n):   # every part requires every other: one knot of 200 parts and 39,800 constraints
        lines.append(f"  p{v}: [{', '.join(f'p{u}' for u in range(n) if u != v)}]")
    path = tmp_path / "dense.yaml"
    path.write_text("\n".join(lines) + "\n")
    with CpuTime() as cpu:
        result = run_cli("relax", path)
    assert cpu.seconds < 20
    assert result.exit_code == 1 and "over the relaxation's limits" in result.stderr
    assert not result.stdout


def test_a_large_sparse_knot_is_answered_within_the_time_limit():
    import random

    rng = random.Random(7)
    n = 150
    arcs = {(i, (i + 1) % n): 1 for i in range(n)}       # a ring ...
    while len(arcs) < MAX_COMPONENT_ARCS // 2:          # ... with random chords, heavier
        u, v = rng.sample(range(n), 2)
        arcs.setdefault((u, v), rng.randint(1, 5))
    message = ""
    with CpuTime() as cpu:
        try:
            weight, cut = min_feedback_arc_set(range(n), arcs, time_limit=1.0)
        except RelaxTimeout as exc:
            weight, cut, message = exc.weight, exc.arcs, str(exc)
    assert cpu.seconds < 5
    assert acyclic(range(n), [a for a in arcs if a not in set(cut)])       # feasible either way
    assert weight == sum(arcs[a] for a in cut)
    assert not message or "not proven minimal" in message
    with pytest.raises(RelaxRefused):
        min_feedback_arc_set(range(n), {(u, v): 1 for u in range(n) for v in range(n) if u != v})


def test_out_of_time_the_best_relaxation_is_written_and_labelled(tmp_path):
    import random

    rng = random.Random(3)
    n = 150
    arcs = {(i, (i + 1) % n) for i in range(n)}
    while len(arcs) < 1000:
        arcs.add(tuple(rng.sample(range(n), 2)))
    requires: dict = {}
    for u, v in sorted(arcs):
        requires.setdefault(f"p{v}", []).append(f"p{u}")
    path = tmp_path / "knot.json"
    path.write_text(json.dumps({"parts": [f"p{i}" for i in range(n)], "requires": requires}))
    result = run_cli("relax", path, "--time-limit", "0.2", "-o", tmp_path / "out.yaml")
    assert result.exit_code == 0, result.output
    assert "NOT PROVEN MINIMAL" in result.stderr and "--time-limit" in result.stderr
    assert run_cli("check", tmp_path / "out.yaml").exit_code == 0
    doc = json.loads(run_cli("relax", path, "--time-limit", "0.2", "--json").stdout)
    assert doc["minimal"] is False and doc["weight"] == len(doc["dropped"]) > 0
