"""AND/OR assembly plans (issue 15): expansion into strategies, checks with lines, limits, the CLI.

The reference is :func:`opportune.formats.andor.sequences`, a brute-force enumerator written
straight from the definition (interleavings of the components' sequences, then the `then` steps);
the engine must count exactly the sequences it lists, from the expanded strategies alone.
"""

from __future__ import annotations

import json
import random

import pytest
from conftest import CpuTime, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune import load_plan
from opportune.engine.schedule import Schedule
from opportune.formats import check_text, plan_from_andor
from opportune.formats.andor import MAX_COMBINATIONS, AndOrGraph, Way, expand, sequences
from opportune.planning.plan import PlanError


def random_andor(seed: int, max_parts: int = 8, max_ways: int = 3):
    """A random AND/OR graph over 2..max_parts parts: ``(parts, assemblies, product)``.

    Each assembly gets 1..max_ways ways; a way takes 0..2 of the assembly's parts as `then` steps
    and splits the rest into blocks (at least two, or one if there are `then` steps); a block of one
    part is that part, a larger block a subassembly (sometimes shared with an earlier one of the same
    parts, as in Homem de Mello & Sanderson's graphs).  Random `before` pairs join in.
    """
    rnd = random.Random(seed)
    parts = [f"p{i}" for i in range(rnd.randint(2, max_parts))]
    assemblies: dict[str, list[dict]] = {}
    by_set: dict[frozenset, str] = {}

    def make(block: list[str]) -> str:
        if len(block) == 1:
            return block[0]
        key = frozenset(block)
        if key in by_set and rnd.random() < 0.6:
            return by_set[key]
        name = f"A{len(assemblies)}"
        assemblies[name] = []
        ways = []
        for w in range(rnd.randint(1, max_ways)):
            items = list(block)
            rnd.shuffle(items)
            then = items[:rnd.randint(0, min(2, len(items) - 1))]  # leave at least one part to join
            rest = items[len(then):]
            k = rnd.randint(1 if then else 2, min(len(rest), 4))
            cuts = sorted(rnd.sample(range(1, len(rest)), k - 1)) if k > 1 else []
            blocks = [rest[a:b] for a, b in zip([0] + cuts, cuts + [len(rest)])]
            join = [make(b) for b in blocks]
            way: dict = {"name": f"w{w}", "join": join}
            if then:
                way["then"] = then
            before = []
            if len(join) >= 2 and rnd.random() < 0.4:
                i, j = sorted(rnd.sample(range(len(join)), 2))
                before.append([join[i], join[j]])
            if len(then) == 2 and rnd.random() < 0.5:
                before.append(list(then))
            if before:
                way["before"] = before
            ways.append(way)
        assemblies[name] = ways
        by_set[key] = name
        return name

    return parts, assemblies, make(list(parts))


def _plan(seed: int, **kw):
    parts, assemblies, product = random_andor(seed, **kw)
    try:
        return plan_from_andor(parts, assemblies, product=product, name=f"random-{seed}")
    except PlanError as exc:  # only the stated limit may refuse a random graph
        assert all(p.code == "limit" for p in exc.problems), str(exc)
        return None


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1))
def test_count_equals_brute_force_enumeration(seed):
    plan = _plan(seed)
    if plan is None or len(plan.strategies) > 12:  # the engine is exact up to 12 strategies
        return
    expected = sequences(plan.andor)
    assert Schedule(plan).count() == len(expected)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_admissible_sequences_equal_brute_force_on_tiny_graphs(seed):
    plan = _plan(seed, max_parts=5)
    if plan is None or len(plan.strategies) > 12:
        return
    assert set(Schedule(plan).completions()) == sequences(plan.andor)


def test_random_graphs_are_mostly_accepted():
    # the property tests above would be empty if the generator made mostly refused graphs
    plans = [_plan(seed) for seed in range(200)]
    usable = [p for p in plans if p is not None and len(p.strategies) <= 12]
    assert len(usable) > 150
    assert sum(len(p.strategies) > 1 for p in usable) > 40


def test_worked_example_has_two_subassembly_orders():
    pump = load_plan("example:pump")
    assert pump.andor is not None and pump.andor.product == "pump"
    assert [s.name for s in pump.strategies] == ["pump=rotor-first,rotor=bearing-first",
                                                 "pump=rotor-first,rotor=impeller-first", "pump=in-place"]
    # genuinely different: the bearing goes onto the shaft in one, the shaft into the bearing in the other
    before = {s.name: s.pairs() for s in pump.strategies}
    assert ("shaft", "bearing") in before["pump=rotor-first,rotor=bearing-first"]
    assert ("bearing", "shaft") in before["pump=in-place"]
    # the four bolts are identical units of one part: the brute force lists parts, the engine units
    assert Schedule(pump).count() == len(sequences(pump.andor)) == 34


def test_expand_deduplicates_and_drops_subsumed_strategies():
    g = AndOrGraph("p", ("a", "b", "c"), (("p", (Way("free", ("a", "b", "c")), Way("same", ("c", "b", "a")),
                                                Way("chain", ("a", "b", "c"), (), (("a", "b"), ("b", "c")))),),))
    strategies = expand(g)
    assert [s.name for s in strategies] == ["p=free"]
    assert dict(strategies[0].requires) == {}


def test_shared_subassembly_and_minimal_constraints():
    plan = plan_from_andor(["a", "b", "c", "d"], {
        "p": [{"name": "x", "join": ["q", "c"], "then": ["d"]}, {"name": "y", "join": ["q"], "then": ["c", "d"],
                                                                  "before": [["d", "c"]]}],
        "q": [{"join": ["a"], "then": ["b"]}]})
    assert [s.name for s in plan.strategies] == ["p=x", "p=y"]
    assert dict(plan.strategies[0].requires) == {"b": ("a",), "d": ("c", "b")} or \
        dict(plan.strategies[0].requires) == {"b": ("a",), "d": ("b", "c")}
    assert dict(plan.strategies[1].requires) == {"b": ("a",), "c": ("d",), "d": ("b",)}


# ---------------------------------------------------------------- checks, with their lines

HEAD = "name: t\nparts: [a, b, c, d]\n"

CASES = [
    # (document after HEAD, code, line, words in the message)
    ("assemblies:\n  p:\n    - join: [a, b, c, x]\n", "unknown-part", 5, "unknown name 'x'"),
    (("assemblies:\n  p:\n    - join: [q, c]\n      then: [d]\n  q:\n    - join: [a, b]\n"
      "  r:\n    - join: [a, b, c]\n      then: [q]\n"), "andor-then", 11, "`then` lists parts"),
    ("assemblies:\n  p:\n    - join: [q, c, d]\n  q:\n    - join: [a, b, c]\n", "andor-twice", 5,
     "uses part 'c' twice"),
    ("assemblies:\n  p:\n    - join: [q, d]\n  q:\n    - join: [a, b, c]\n    - join: [a, b]\n",
     "andor-parts", 8, "makes other parts"),
    ("assemblies:\n  p:\n    - join: [q, d]\n  q:\n    - join: [r, c]\n  r:\n    - join: [q, a, b]\n",
     "cycle", 7, "contains itself"),
    ("assemblies:\n  p:\n    - join: [a, b, c]\n", "andor-unreachable", 2, "part 'd' is not used"),
    ("assemblies:\n  p:\n    - join: [p, a, b, c, d]\n", "cycle", 5, "contains itself"),
    ("assemblies:\n  p:\n    - join: [q, c, d]\n  q:\n    - join: [a]\n      then: [b]\n    - join: [a]\n",
     "andor-way", 9, "single component"),
    ("assemblies:\n  p:\n    - join: [a, b, c, d]\n      before: [[a, b], [b, a]]\n", "cycle", 6, "make a cycle"),
    ("assemblies:\n  p:\n    - join: [a, b, c]\n      then: [d]\n      before: [[a, d]]\n", "andor-before", 7,
     "two components"),
    ("product: z\nassemblies:\n  p:\n    - join: [a, b, c, d]\n", "andor-product", 3, "not an assembly"),
    ("assemblies:\n  a:\n    - join: [b, c, d]\n", "andor-name", 4, "both a part and an assembly"),
    ("requires: {b: [a]}\nassemblies:\n  p:\n    - join: [a, b, c, d]\n", "conflict", 3, "both `requires`"),
    ("assemblies:\n  p:\n    - name: one\n      join: [a, b, c, d]\n    - name: one\n      join: [d, c, b, a]\n",
     "andor-way", 7, "two ways named 'one'"),
]


@pytest.mark.parametrize("body,code,line,words", CASES)
def test_each_check_has_its_line(body, code, line, words):
    result = check_text(HEAD + body, file="t.yaml")
    assert not result.ok and result.plan is None
    found = [p for p in result.errors if p.code == code]
    assert found, [str(p) for p in result.problems]
    assert found[0].line == line and found[0].file == "t.yaml", str(found[0])
    assert words in found[0].message, str(found[0])


def test_unreachable_assembly_is_a_warning():
    result = check_text(HEAD + "assemblies:\n  p:\n    - join: [a, b, c, d]\n  q:\n    - join: [a, b]\n", file="t.yaml")
    assert result.ok
    [w] = result.warnings
    assert w.code == "andor-unreachable" and w.line == 6 and "'q' is not used" in w.message


def test_schema_documents_assemblies():
    result = run_cli("schema")
    schema = json.loads(result.output)
    assert "assemblies" in schema["properties"] and "way" in schema["$defs"]
    assert set(schema["$defs"]["way"]["properties"]) == {"name", "description", "join", "then", "before"}
    bad = check_text(HEAD + "assemblies:\n  p:\n    - join: [a, b, c, d]\n      bfore: []\n", file="t.yaml")
    assert [(p.code, p.line) for p in bad.errors] == [("unknown-field", 6)] and "`before`" in bad.errors[0].hint


# ---------------------------------------------------------------- limits


def _chain(k: int, choice: bool = True) -> dict:
    parts = [f"x{i}" for i in range(k + 1)]
    assemblies = {}
    for i in range(k):
        sub = f"A{i + 1}" if i < k - 1 else parts[k]
        ways = [{"name": "l", "join": [parts[i], sub]}]
        if choice:
            ways.append({"name": "r", "join": [sub], "then": [parts[i]]})
        assemblies[f"A{i}"] = ways
    return {"name": "chain", "parts": parts, "assemblies": assemblies}


def test_too_many_combinations_refused_fast():
    doc = _chain(20)  # 2^20 combinations of ways
    with CpuTime() as cpu:
        result = check_text(json.dumps(doc), fmt="json", file="big.json")
    assert cpu.seconds < 1.0            # refused by counting, not by trying the combinations
    [p] = result.errors
    assert p.code == "limit" and "1,048,576 combinations" in p.message and f"at most {MAX_COMBINATIONS:,}" in p.message
    assert "A0: 2 ways" in p.message and p.line == 1


def test_too_many_distinct_strategies_refused():
    doc = _chain(7)
    for i, ways in enumerate(doc["assemblies"].values()):  # 128 different total orders
        ways[0]["before"] = [list(ways[0]["join"])]
        ways[1] = {"name": "r", "join": list(reversed(ways[0]["join"])), "before": [list(reversed(ways[0]["join"]))]}
    with pytest.raises(PlanError, match="more than 64 different partial orders"):
        plan_from_andor(doc["parts"], doc["assemblies"])


def test_hostile_graphs_refused_or_read_quickly():
    with CpuTime() as cpu:
        # 1,000 nested choices: the count is capped, never a huge number
        result = check_text(json.dumps(_chain(1000)), fmt="json")
        assert [p.code for p in result.errors] == ["limit"] and "more than 10^12" in result.errors[0].message
        # a deep chain of subassemblies without choice: no recursion limit
        plan = plan_from_andor(**{k: v for k, v in _chain(1500, choice=False).items() if k != "name"})
        assert [dict(s.requires) for s in plan.strategies] == [{}]  # joins without `then`: any order
        # an alias-free document full of cycles reports a few, quickly
        cyc = {"parts": ["a", "b"], "assemblies": {f"C{i}": [{"join": [f"C{(i + 1) % 300}", "a"]}] for i in range(300)}}
        result = check_text(json.dumps(cyc), fmt="json")
        assert result.errors and all(p.code == "cycle" for p in result.errors)
    assert cpu.seconds < 10


# ---------------------------------------------------------------- command line


def test_cli_check_count_replay_simulate_graph_on_the_example(tmp_path):
    out = run_cli("check", "example:pump")
    assert out.exit_code == 0 and "strategies: 3" in out.output and "pump=in-place" in out.output
    out = run_cli("count", "example:pump", "--json")
    assert out.exit_code == 0, out.output
    assert json.loads(out.output)["sequences"] == "34" and json.loads(out.output)["exact"] is True
    looks = tmp_path / "pump.looks"
    looks.write_text("\n".join(["housing", "bearing", "shaft", "key", "impeller", "seal", "cover",
                                "bolt", "bolt", "bolt", "bolt"]) + "\n")
    out = run_cli("replay", "example:pump", looks, "--json")
    assert out.exit_code == 0, out.output
    trace = json.loads(out.output)
    # each look shows the next part of an in-place sequence: all installed straight from the bin
    assert [t["action"]["kind"] for t in trace] == ["install"] * 11 + ["done"]
    schedule = Schedule(load_plan("example:pump"))
    for step in ["housing", "bearing", "shaft"]:
        schedule = schedule.install(step)
    assert schedule.consistent_strategies == ("pump=in-place",)
    out = run_cli("simulate", "example:pump", "--trials", "20", "--workers", "1", "--json")
    assert out.exit_code == 0, out.output
    dot = run_cli("graph", "example:pump")
    assert dot.exit_code == 0 and "rotor-first" in dot.output and "shape=box" in dot.output
    orders = run_cli("graph", "example:pump", "--orders")
    assert orders.exit_code == 0 and "cluster_2" in orders.output and "rotor-first" in orders.output


def test_cli_check_reports_andor_problems_with_lines(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(HEAD + "assemblies:\n  p:\n    - join: [q, c, d]\n  q:\n    - join: [a, b, c]\n")
    out = run_cli("check", bad)
    assert out.exit_code == 1 and f"{bad}:5: error: way '1' of 'p' uses part 'c' twice" in out.output.replace("\n", "")
    out = run_cli("check", bad, "--json")
    doc = json.loads(out.output)
    assert doc["valid"] is False and doc["problems"][0]["line"] == 5 and doc["problems"][0]["code"] == "andor-twice"


def test_the_service_runs_an_andor_plan(tmp_path):
    from contextlib import closing

    from opportune.datasets import example_path
    from opportune.service.testing import Client, ServiceProcess

    # the client closed with the server: left open, its socket waited in a reference cycle and was reported
    # unclosed (ResourceWarning) in whichever later test the garbage collector ran
    with ServiceProcess(tmp_path / "api.db", log=tmp_path / "api.log") as svc, \
            closing(Client(svc.url, svc.token(cell="cell-a"))) as client:
        r = client.post("/plans", content=example_path("pump").read_text(),
                        headers={"Content-Type": "application/yaml"}, key=False)
        assert r.status_code == 201, r.text
        r = client.post("/runs", {"plan": r.json()["id"]})
        assert r.status_code == 201, r.text
        run = r.json()["id"]
        actions = []
        for part in ["housing", "bearing", "shaft", "key", "impeller", "seal", "cover"] + ["bolt"] * 4:
            for _ in range(20):  # a busy machine may pass a decision's deadline: retry, as a cell would
                r = client.post(f"/runs/{run}/looks", {"visible": [part]})
                if r.status_code != 503:
                    break
            assert r.status_code == 200, r.text
            actions.append((r.json()["action"]["kind"], r.json()["action"].get("part")))
            outcome = client.post(f"/runs/{run}/outcomes", {"outcome": "success"})
            assert outcome.status_code == 200
        assert actions[:3] == [("install", "housing"), ("install", "bearing"), ("install", "shaft")]
        assert outcome.json()["run"]["status"] == "complete"        # at the last bolt
        assert len(client.get(f"/runs/{run}/graph").json()["strategies"]) == 3  # one layout per strategy


def test_module_examples():
    import doctest

    from opportune.formats import andor

    assert doctest.testmod(andor).failed == 0


def test_the_docs_show_the_example_as_it_ships():
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "andor.md").read_text(encoding="utf-8")
    shown = check_text(re.findall(r"```yaml\n(.*?)```", page, flags=re.S)[0], file="docs/andor.md")
    assert shown.ok, [str(p) for p in shown.problems]
    shipped = load_plan("example:pump")
    assert [(s.name, dict(s.requires)) for s in shown.plan.strategies] == \
        [(s.name, dict(s.requires)) for s in shipped.strategies]
