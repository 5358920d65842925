"""Plans written as ways: the form (files, checks, bounds), the exact count against brute force and against
the partial-order engine, the estimate's stated interval, and the schedule's questions on such plans."""

from __future__ import annotations

import itertools
import random

import pytest
from hypothesis import given, settings, strategies as st

from opportune.engine import NotAdmissible, OrderEngine, Schedule
from opportune.engine.deadline import BudgetExceeded, Deadline
from opportune.engine.ways import WaysCounter, estimate_completions
from opportune.formats.loader import check_text, make_plan, plan_from_dict
from opportune.formats.ways import ways_of_strategy, ways_plan
from opportune.limits import MAX_WAYS
from opportune.planning.plan import Part, Way
from opportune.planning.ways import WaysTable, unit_id


def random_ways_plan(rng: random.Random, n: int, max_ways: int = 3, needs: bool = True):
    """A random plan written as ways over ``n`` parts (feasible or not)."""
    ids = [f"p{i}" for i in range(n)]
    ways = {}
    for p in ids:
        others = [q for q in ids if q != p]
        listed = []
        for _ in range(rng.randint(1, max_ways)):
            blockers = frozenset(q for q in others if rng.random() < 0.3)
            need = ()
            if needs and rng.random() < 0.4:
                need = (frozenset(rng.sample(others, rng.randint(1, min(3, len(others))))),) if others else ()
            listed.append(Way(blockers, need, first=rng.random() < 0.1))
        if rng.random() < 0.85:
            ways[p] = listed
    return ways_plan("random", [Part(p) for p in ids], ways)


def admitted(plan, sequence) -> bool:
    """The definition: each part, when it goes in, has a way that admits what is in."""
    ways = plan.ways
    installed: set[str] = set()
    for p in sequence:
        if p in ways and not any(w.admits(installed) for w in ways[p]):
            return False
        installed.add(p)
    return True


def brute(plan) -> list[tuple[str, ...]]:
    return [s for s in itertools.permutations(plan.part_ids) if admitted(plan, s)]


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6), st.integers(0, 10**9))
def test_the_exact_count_and_the_schedule_admit_exactly_the_brute_forces_sequences(n, seed):
    plan = random_ways_plan(random.Random(seed), n)
    good = brute(plan)
    engine = OrderEngine(plan)
    assert Schedule(engine).count() == len(good)
    assert WaysCounter(WaysTable.of(plan)).count(0) == len(good)
    good_set = set(good)
    for seq in itertools.permutations(plan.part_ids):
        s = Schedule(engine)
        try:
            for p in seq:
                s = s.install(p)
            ok = True
        except NotAdmissible:
            ok = False
        assert ok == (seq in good_set), seq
    # dead-end awareness: every installable part leads to a set with a completion
    if good:
        s = Schedule(engine)
        walk = random.Random(seed)
        while not s.is_complete:
            options = s.options()
            assert options and all(v > 0 for v in options.values())
            assert set(options) == set(s.installable())
            s = s.install(walk.choice(sorted(options)))


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 7), st.integers(0, 10**9))
def test_one_strategy_written_as_ways_counts_and_answers_as_the_order_engine(n, seed):
    rng = random.Random(seed)
    ids = [f"p{i}" for i in range(n)]
    requires = {ids[j]: [ids[i] for i in range(j) if rng.random() < 0.35] for j in range(n)}
    plan = make_plan(ids, requires)
    ways = ways_of_strategy(plan)
    order, by_ways = Schedule(plan), Schedule(ways)
    assert type(by_ways.engine).__name__ == "WaysEngine"
    assert order.count() == by_ways.count()
    assert order.installable() == by_ways.installable()
    assert order.options() == by_ways.options()
    assert order.expected_positions() == by_ways.expected_positions()
    first = order.installable()[0]
    assert order.install(first).options() == by_ways.install(first).options()


def test_the_estimate_is_seeded_and_its_interval_holds_the_count_mostly():
    rng = random.Random(3)
    # (the exact counts by the counter, which the test above checks against brute force)
    plans = [p for p in (random_ways_plan(rng, 9) for _ in range(40)) if WaysCounter(WaysTable.of(p)).count(0)][:6]
    assert len(plans) >= 4
    held = tried = 0
    for plan in plans:
        exact = WaysCounter(WaysTable.of(plan)).count(0)
        table = WaysTable.of(plan)
        for seed in range(4):
            r = estimate_completions(table, seed=seed, rel_error=0.05, max_runs=40, particles=8)
            again = estimate_completions(table, seed=seed, rel_error=0.05, max_runs=40, particles=8)
            assert (r.value, r.rel_error) == (again.value, again.rel_error)
            assert not r.exact and r.method == "ways-smc" and r.confidence == 0.95
            tried += 1
            held += abs(r.value - exact) <= r.rel_error * r.value + 1e-9
    assert held >= 0.8 * tried, (held, tried)


def test_an_exact_count_over_its_budget_raises_and_count_result_estimates_instead():
    plan = ways_plan("free", [Part(f"p{i}") for i in range(14)], {})
    counter = WaysCounter(WaysTable.of(plan), max_memo=100)
    with pytest.raises(BudgetExceeded) as info:
        counter.count(0)
    assert info.value.reason == "memo"
    with pytest.raises(BudgetExceeded) as info:
        WaysCounter(WaysTable.of(plan)).count(0, Deadline.after(-1.0))
    assert info.value.reason == "time"
    engine = OrderEngine(plan, max_memo=100)
    r = Schedule(engine).count_result(time_limit=0.5, seed=1)
    assert not r.exact and r.method == "ways-smc"
    assert abs(r.log10 - 10.940408) < 1e-6       # every run says 14!: no spread
    assert Schedule(OrderEngine(ways_plan("few", [Part("a"), Part("b")], {}))).count_result().value == 2


WAYS_YAML = """name: peg
parts: [base, peg, cap]
ways:
  peg:
    - {name: +z, blockers: [cap], after: [base]}
    - {name: -x, needs: [[base, cap]]}
  cap:
    - {after: [base]}
"""


def test_a_ways_file_reads_writes_back_and_counts():
    result = check_text(WAYS_YAML, file="peg.yaml")
    assert result.ok, result.problems
    plan = result.plan
    assert plan.is_ways and plan.strategies == ()
    assert plan_from_dict(plan.to_dict(), file="peg.yaml") == plan
    assert Schedule(plan).count() == len(brute(plan)) == 2
    with pytest.raises(NotAdmissible, match="requires base first"):
        Schedule(plan).install("cap")


@pytest.mark.parametrize("text, code", [
    ("parts: [a, b]\nrequires: {b: [a]}\nways: {a: [{blockers: [b]}]}\n", "conflict"),
    ("parts: [a, b]\nways: {a: [{blockers: [c]}]}\n", "unknown-part"),
    ("parts: [a, b]\nways: {a: [{blockers: [a]}]}\n", "self-requirement"),
    ("parts: [a, {id: b, quantity: 2}]\nways: {a: [{blockers: [b#3]}]}\n", "unknown-part"),
    ("parts: [a, b]\nways: {a: [{blockers: [b#1]}]}\n", "unknown-part"),
    ("parts: [a, {id: b, quantity: 2}]\nways: {b#3: [{blockers: [a]}]}\n", "unknown-part"),
    ("parts: [a, {id: b, quantity: 2}]\nways: {b#2: [{after: [b]}]}\n", "self-requirement"),
    ("parts: [a, {id: b, quantity: 2}]\nways: {b: [{needs: [[b#1, a]]}]}\n", "self-requirement"),
    ("parts: [a, b]\nways: {a: [{blockers: [b], after: [b]}]}\n", "ways-contradiction"),
    ("parts: [a, b]\nways: {a: [{blockers: [b]}], b: [{blockers: [a]}]}\n", "ways-infeasible"),
    ("parts: [a, b]\nways: {a: [{name: \"x\\e[31m\"}]}\n", "text"),
    ("parts: [a, b]\nways: {a: [{blockers: [b], sideways: 1}]}\n", "unknown-field"),
    ("parts: [a, b]\nways: {a: []}\n", "empty"),
])
def test_bad_ways_are_refused_with_a_problem_each(text, code):
    result = check_text(text, file="w.yaml")
    assert not result.ok
    assert code in {p.code for p in result.errors}, [str(p) for p in result.errors]


def test_more_part_ids_in_the_ways_than_the_limit_are_refused(monkeypatch):
    from opportune.formats import ways as ways_format

    monkeypatch.setattr(ways_format, "MAX_CONSTRAINTS", 3)
    result = check_text("parts: [a, b, c]\nways: {a: [{blockers: [b, c]}], b: [{after: [c]}, {needs: [[a, c]]}]}\n",
                        file="w.yaml")
    assert not result.ok and [p.code for p in result.errors] == ["limit"]
    assert "5 parts in all; at most 3" in result.errors[0].message


def test_more_ways_than_the_limit_are_refused_before_anything_is_built():
    many = ", ".join("{blockers: [b]}" for _ in range(MAX_WAYS + 1))
    result = check_text(f"parts: [a, b]\nways: {{a: [{many}]}}\n", file="w.yaml")
    assert not result.ok and any(str(MAX_WAYS) in p.message for p in result.errors)


def test_a_ways_plans_text_is_escaped_where_a_terminal_shows_it():
    from opportune.cli_count import printable

    result = check_text("name: \"a\\e]0;x\"\nparts: [a]\nways: {a: [{}]}\n", file="w.yaml")
    assert not result.ok and any(p.code == "text" for p in result.errors)
    assert "\x1b" not in printable("a\x1b]0;x")


@settings(max_examples=15, deadline=None)
@given(st.integers(2, 8), st.integers(0, 10**9))
def test_the_sequencer_installs_only_admitted_sequences_of_a_ways_plan_and_finishes(n, seed):
    from opportune.sequencer import Sequencer

    rng = random.Random(seed)
    plan = random_ways_plan(rng, n)
    if not WaysCounter(WaysTable.of(plan)).count(0):
        return
    seq = Sequencer(plan, buffer_capacity=None, budget=None)
    for _ in range(20 * n):
        if seq.state.is_complete:
            break
        left = [p for p, k in seq.state.schedule.remaining.items() if p not in seq.state.buffer]
        seq.step(rng.sample(left, min(len(left), 2)) if left else [])
    assert seq.state.is_complete
    assert admitted(plan, seq.state.installed)


def test_check_count_and_replay_take_a_ways_file(tmp_path):
    from typer.testing import CliRunner

    from opportune.cli import app

    runner = CliRunner()
    path = tmp_path / "peg.yaml"
    path.write_text(WAYS_YAML)
    checked = runner.invoke(app, ["check", str(path)])
    assert checked.exit_code == 0 and "written as ways: 3 ways for 2 listed parts" in checked.output
    counted = runner.invoke(app, ["count", "--json", "--after", "base", str(path)])
    assert counted.exit_code == 0 and '"sequences": "2"' in counted.output
    refused = runner.invoke(app, ["count", "--after", "cap", str(path)])
    assert refused.exit_code == 1 and "requires base first" in refused.output
    looks = tmp_path / "looks.txt"
    looks.write_text("peg cap\nbase\ncap\n-\n")
    replayed = runner.invoke(app, ["replay", str(path), str(looks)])
    assert replayed.exit_code == 0 and "complete: base,cap,peg" in replayed.output


@pytest.mark.parametrize("args", [["graph"], ["convert"]])
def test_commands_that_do_not_take_ways_plans_yet_say_so_without_a_traceback(tmp_path, args):
    from typer.testing import CliRunner

    from opportune.cli import app

    path = tmp_path / "peg.yaml"
    path.write_text(WAYS_YAML)
    looks = tmp_path / "looks.txt"
    looks.write_text("base\n")
    extra = {"convert": [str(tmp_path / "out.dot")], "replay": [str(looks)]}.get(args[0], [])
    result = CliRunner().invoke(app, [args[0], str(path), *extra, *args[1:]])
    assert result.exit_code in (1, 2) and "Traceback" not in result.output
    assert "does not take a plan written as ways yet" in result.output, result.output


def test_the_checks_search_for_a_sequence_is_bounded_and_warns_when_cut(monkeypatch):
    from opportune.formats import ways as ways_format

    # 12 free parts but one that must go in first while another is in: undecidable within 3 sets
    text = "parts: [" + ", ".join(f"p{i}" for i in range(12)) + "]\nways: {p0: [{after: [p1], blockers: [p2]}]}\n"
    assert check_text(text, file="w.yaml").ok
    monkeypatch.setattr(ways_format, "SEARCH_WORK", 3)
    result = check_text(text, file="w.yaml")
    assert result.ok and [p.code for p in result.warnings] == ["ways-undecided"]
    monkeypatch.setattr(ways_format, "SEARCH_WORK", 10**9)
    monkeypatch.setattr(ways_format, "SEARCH_SECONDS", -1.0)      # no time at all: cut at once
    result = check_text(text, file="w.yaml")
    assert result.ok and [p.code for p in result.warnings] == ["ways-undecided"]


def random_units_plan(rng: random.Random, n: int) -> tuple:
    """A random plan written as ways whose parts have 1 or 2 units, each unit its own ways naming units."""
    quantity = {f"p{i}": rng.choice((1, 1, 2)) for i in range(n)}
    units = [unit_id(p, k) if q > 1 else p for p, q in quantity.items() for k in range(1, q + 1)]
    ways = {}
    for u in units:
        others = [x for x in units if x.split("#")[0] != u.split("#")[0]]
        listed = []
        for _ in range(rng.randint(1, 2)):
            need = (frozenset(rng.sample(others, min(2, len(others)))),) if others and rng.random() < 0.3 else ()
            held = set().union(*need)     # a part needed is no blocker (the file refuses that contradiction)
            listed.append(Way(frozenset(x for x in others if x not in held and rng.random() < 0.3), need))
        if rng.random() < 0.85:
            ways[u] = listed
    return ways_plan("units", [Part(p, quantity=q) for p, q in quantity.items()], ways), quantity


def admitted_units(plan, quantity: dict, sequence) -> bool:
    """The definition with units: the k-th time a part goes in, its k-th unit has a way that admits the
    units in (a unit not listed goes in whenever its turn comes)."""
    installed: set[str] = set()
    seen: dict[str, int] = {}
    for p in sequence:
        seen[p] = seen.get(p, 0) + 1
        unit = unit_id(p, seen[p]) if quantity[p] > 1 else p
        ways = plan.ways.get(unit)
        if ways and not any(w.admits(installed) for w in ways):
            return False
        installed.add(unit)
    return True


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 4), st.integers(0, 10**9))
def test_parts_of_several_units_count_and_install_as_the_definition_says(n, seed):
    """A part of quantity 2 in a plan written as ways: its units go in in turn, each by its own ways; the
    count is the number of distinct sequences of part ids the definition admits, the schedule installs
    exactly those (naming the part, not a unit), and the file form reads back the same plan."""
    plan, quantity = random_units_plan(random.Random(seed), n)
    multiset = [p for p, q in quantity.items() for _ in range(q)]
    good = {s for s in itertools.permutations(multiset) if admitted_units(plan, quantity, s)}
    assert Schedule(plan).count() == len(good)
    for seq in set(itertools.permutations(multiset)):
        s = Schedule(plan)
        try:
            for p in seq:
                s = s.install(p)
            ok = True
        except NotAdmissible:
            ok = False
        assert ok == (seq in good), seq
    if good:
        back = check_text(__import__("yaml").safe_dump(plan.to_dict()), file="u.yaml")
        assert back.ok and Schedule(back.plan).count() == len(good)


def test_a_bare_id_of_a_part_of_several_is_its_first_unit_in_blockers_and_its_last_in_after():
    text = ("parts: [{id: s, quantity: 2}, a, b]\n"
            "ways: {a: [{blockers: [s]}], b: [{after: [s]}]}\n")
    plan = check_text(text, file="s.yaml").plan
    assert {tuple(sorted(w.blockers)) for w in plan.ways["a"]} == {("s#1",)}
    assert [sorted(n) for w in plan.ways["b"] for n in w.needs] == [["s#2"]]
    orders = {s for s in set(itertools.permutations(["s", "s", "a", "b"]))
              if Schedule(plan, s[:0]).count() and _installs(plan, s)}
    assert orders == {s for s in set(itertools.permutations(["s", "s", "a", "b"]))
                      if s.index("a") < s.index("s") and s.index("b") > len(s) - 1 - s[::-1].index("s")}


def _installs(plan, sequence) -> bool:
    s = Schedule(plan)
    try:
        for p in sequence:
            s = s.install(p)
    except NotAdmissible:
        return False
    return True
