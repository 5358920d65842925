"""Plan files: loading, every kind of bad input, and the messages users see."""

from __future__ import annotations

import json
import textwrap

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import GEARBOX, SALBP_FILES
from opportune import PlanError, load_plan, make_plan
from opportune.formats import check_text, read_plan
from opportune.formats.validate import find_cycles


def check_yaml(text: str):
    return check_text(textwrap.dedent(text), fmt="yaml", file="plan.yaml")


def only_error(result, code):
    errors = [p for p in result.errors if p.code == code]
    assert errors, f"no {code} error in {[str(p) for p in result.problems]}"
    return errors[0]


def test_gearbox_loads_in_declaration_order():
    plan = load_plan(GEARBOX)
    assert plan.name == "gearbox"
    assert plan.part_ids == ("ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl")
    assert len(plan.strategies) == 1
    assert set(plan.strategies[0].requires["co"]) == {"rl", "dr", "ml", "ra"}
    assert plan.part("co").name == "cover"


def test_yaml_and_json_give_the_same_plan(tmp_path):
    plan = load_plan(GEARBOX)
    path = tmp_path / "gearbox.json"
    path.write_text(json.dumps(plan.to_dict(), indent=1))
    again = load_plan(path)
    assert again.parts == plan.parts
    assert [dict(s.requires) for s in again.strategies] == [dict(s.requires) for s in plan.strategies]


def test_part_mappings_and_defaults():
    result = check_yaml("""
        parts:
          - {id: sc, name: screw, quantity: 4, acquire: 0.5, install: 2}
          - co
        requires: {sc: co}
        """)
    assert result.ok, result.problems
    sc = result.plan.part("sc")
    assert (sc.quantity, sc.acquire, sc.install, sc.name) == (4, 0.5, 2.0, "screw")
    assert result.plan.part("co").cost == 2.0
    assert result.plan.n_units == 5


def test_several_strategies():
    result = check_yaml("""
        parts: [a, b, c]
        strategies:
          - {name: left, requires: {c: [a]}}
          - {name: right, requires: {c: [b]}}
        """)
    assert result.ok
    assert [s.name for s in result.plan.strategies] == ["left", "right"]


def test_integer_ids_are_strings():
    result = check_yaml("""
        parts: [1, 2, 3]
        requires: {3: [1, 2]}
        """)
    assert result.ok, result.problems
    assert result.plan.part_ids == ("1", "2", "3")
    assert result.plan.strategies[0].requires["3"] == ("1", "2")


# ---------------------------------------------------------------- bad input, one test each


def test_yaml_syntax_error_has_line():
    result = check_yaml("""
        parts: [a, b
        requires:
          b: [a]
        """)
    p = only_error(result, "syntax")
    assert p.line is not None and p.file == "plan.yaml"
    assert "YAML syntax error" in p.message


def test_json_syntax_error_has_line():
    result = check_text('{\n  "parts": ["a", "b"],\n  "requires": {"b": ["a"],}\n}\n', fmt="json", file="p.json")
    p = only_error(result, "syntax")
    assert p.line == 3
    assert "trailing comma" in p.hint


def test_unknown_part_is_named_with_a_suggestion():
    result = check_yaml("""
        parts: [case, base]
        requires:
          base: [cace]
        """)
    p = only_error(result, "unknown-part")
    assert p.parts == ("cace",) and p.line == 4
    assert "did you mean 'case'" in p.hint


def test_unknown_part_as_key():
    p = only_error(check_yaml("parts: [a]\nrequires: {b: [a]}\n"), "unknown-part")
    assert "'b'" in p.message and "declare it under `parts`" in p.hint


def test_duplicate_part_ids():
    p = only_error(check_yaml("parts:\n  - a\n  - b\n  - a\n"), "duplicate-part")
    assert p.line == 4 and "first declared at line 2" in p.message and "quantity" in p.hint


def test_part_requiring_itself():
    p = only_error(check_yaml("parts: [a, b]\nrequires: {b: [b, a]}\n"), "self-requirement")
    assert p.parts == ("b",) and p.line == 2


def test_cycle_is_printed():
    result = check_yaml("""
        parts: [ca, ba, rl]
        requires:
          ba: [ca, rl]
          rl: [ba]
        """)
    p = only_error(result, "cycle")
    assert "ba -> rl -> ba" in p.message
    assert "no admissible sequence" in p.message


def test_long_cycle_and_two_separate_cycles():
    result = check_yaml("""
        parts: [a, b, c, d, e]
        requires: {b: [a], c: [b], a: [c], e: [d], d: [e]}
        """)
    cycles = [p.message for p in result.errors if p.code == "cycle"]
    assert len(cycles) == 2
    assert any("a -> b -> c -> a" in m for m in cycles)
    assert any("d -> e -> d" in m for m in cycles)


def test_duplicate_strategies():
    result = check_yaml("""
        parts: [a, b, c]
        strategies:
          - {name: one, requires: {c: [a, b], b: [a]}}
          - {name: two, requires: {c: [b], b: [a]}}
        """)
    p = only_error(result, "duplicate-strategy")
    assert "'one' and 'two' admit exactly the same sequences" in p.message


def test_duplicate_strategy_names():
    result = check_yaml("""
        parts: [a, b]
        strategies:
          - {name: s, requires: {b: [a]}}
          - {name: s, requires: {a: [b]}}
        """)
    assert "two strategies are named 's'" in only_error(result, "duplicate-strategy").message


def test_wrong_types():
    result = check_yaml("""
        parts:
          - {id: a, quantity: four}
          - {id: b, acquire: fast}
        requires: [a, b]
        """)
    msgs = [p.message for p in result.errors]
    assert any("quantity" in m and "expected integer" in m for m in msgs), msgs
    assert any("acquire" in m and "expected number" in m for m in msgs), msgs
    assert any("requires" in m for m in msgs), msgs
    lines = sorted(p.line for p in result.errors)
    assert lines[0] == 3


def test_boolean_looking_ids_are_explained():
    result = check_yaml("parts: [on, off]\n")
    assert any("quote it" in p.message for p in result.errors)


def test_quantity_below_one():
    p = only_error(check_yaml("parts:\n  - {id: sc, quantity: 0}\n"), "quantity")
    assert "at least 1" in p.message and p.line == 2


def test_negative_costs():
    result = check_yaml("parts:\n  - {id: a, acquire: -1}\n  - {id: b, install: -0.5}\n")
    errors = [p for p in result.errors if p.code == "negative-cost"]
    assert [p.line for p in errors] == [2, 3]
    assert "cannot be negative" in errors[0].hint


def test_unknown_field_suggests():
    p = only_error(check_yaml("parts: [a]\nrequire: {a: []}\n"), "unknown-field")
    assert "`require`" in p.message and "did you mean `requires`" in p.hint and p.line == 2


def test_requires_and_strategies_together():
    result = check_yaml("parts: [a]\nrequires: {}\nstrategies: [{requires: {}}]\n")
    assert only_error(result, "conflict")


def test_missing_and_empty_parts():
    assert only_error(check_yaml("name: x\n"), "missing")
    assert only_error(check_yaml("parts: []\n"), "empty")
    assert only_error(check_yaml(""), "empty")
    assert only_error(check_yaml("- a\n- b\n"), "type")


def test_duplicate_yaml_keys():
    p = only_error(check_yaml("parts: [a, b]\nrequires:\n  b: [a]\n  b: []\n"), "duplicate-key")
    assert p.line == 4


def test_invalid_part_id_characters():
    p = only_error(check_yaml("parts: ['a b', c]\n"), "part-id")
    assert "spaces" in p.hint


def test_yaml_loading_is_safe(tmp_path):
    marker = tmp_path / "pwned"
    result = check_yaml(f"""
        parts: !!python/object/apply:os.system ["touch {marker}"]
        """)
    assert not result.ok
    assert not marker.exists()


def test_every_problem_is_reported_not_just_the_first():
    result = check_yaml("""
        parts:
          - a
          - a
          - {id: b, quantity: 0}
        requires:
          c: [a]
        """)
    codes = {p.code for p in result.errors}
    # Schema problems are reported first (the rest needs a well-formed document)...
    assert "quantity" in codes
    result = check_yaml("""
        parts: [a, a, b]
        requires:
          c: [a]
          b: [b, zz]
        """)
    codes = {p.code for p in result.errors}
    assert {"duplicate-part", "unknown-part", "self-requirement"} <= codes


def test_redundant_constraint_is_a_warning_with_the_chain():
    result = check_yaml("parts: [a, b, c]\nrequires: {b: [a], c: [b, a]}\n")
    assert result.ok
    w = [p for p in result.warnings if p.code == "redundant"]
    assert len(w) == 1 and "a -> b -> c" in w[0].message and w[0].line == 2


def test_subsumed_strategy_is_a_warning():
    result = check_yaml("""
        parts: [a, b, c]
        strategies:
          - {name: loose, requires: {c: [a]}}
          - {name: tight, requires: {c: [a, b]}}
        """)
    assert result.ok
    assert any(p.code == "subsumed-strategy" and "'tight' is also admitted by 'loose'" in p.message
               for p in result.warnings)


def test_missing_file_and_directory(tmp_path):
    assert only_error(read_plan(tmp_path / "nope.yaml"), "io")
    assert only_error(read_plan(tmp_path), "io")


def test_load_plan_raises_plan_error_with_all_problems(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("parts: [a, b]\nrequires: {b: [x], a: [y]}\n")
    with pytest.raises(PlanError) as info:
        load_plan(path)
    assert len(info.value.problems) == 2
    assert "bad.yaml:2" in str(info.value)


def test_make_plan_validates():
    with pytest.raises(PlanError, match="cycle"):
        make_plan(["a", "b"], {"a": ["b"], "b": ["a"]})
    plan = make_plan(["a", "b"], strategies={"x": {"b": ["a"]}, "y": {"a": ["b"]}})
    assert len(plan.strategies) == 2


# ---------------------------------------------------------------- SALBP


def test_every_shared_salbp_file_loads(salbp):
    from opportune.formats.salbp import read_in2

    for name in SALBP_FILES:
        path = salbp / f"{name}.IN2"
        raw = read_in2(path)
        plan = load_plan(path)
        assert len(plan.parts) == raw.n
        assert plan.part_ids == tuple(str(i) for i in range(1, raw.n + 1))
        assert [p.install for p in plan.parts] == list(raw.durations)
        assert sum(len(v) for v in plan.strategies[0].requires.values()) == len(set(raw.pairs))


def test_arc111_trailer_is_ignored(salbp):
    from opportune.formats.salbp import read_in2

    raw = read_in2(salbp / "ARC111.IN2")
    assert raw.n == 111 and "gel" in raw.trailer
    assert all(1 <= a <= 111 and 1 <= b <= 111 for a, b in raw.pairs)


def test_bad_in2_files(tmp_path):
    def check(content: bytes):
        path = tmp_path / "x.IN2"
        path.write_bytes(content)
        return read_plan(path)

    assert "tasks are numbered 1..3" in check(b"3\r\n1\r\n1\r\n1\r\n1,4\r\n-1,-1\r\n").errors[0].message
    p = check(b"3\r\n1\r\n1\r\n1\r\n1;2\r\n-1,-1\r\n").errors[0]
    assert p.line == 5 and "not 'i,j'" in p.message
    assert "ends after 2 of 3" in check(b"3\r\n1\r\n1\r\n").errors[0].message
    assert "number of tasks" in check(b"three\r\n").errors[0].message
    assert "requires itself" in check(b"2\r\n1\r\n1\r\n2,2\r\n-1,-1\r\n").errors[0].message
    cyc = check(b"2\r\n1\r\n1\r\n1,2\r\n2,1\r\n-1,-1\r\n")
    assert any("1 -> 2 -> 1" in p.message for p in cyc.errors)
    # Blank lines and LF ends are tolerated; a missing end marker is not (issue 12: a file cut short
    # would be a valid graph with fewer constraints, and its count wrong).
    ok = check(b"2\n\n5\n7\n1,2\n-1,-1\n")
    assert ok.ok and ok.plan.part("2").install == 7
    cut = check(b"2\n\n5\n7\n1,2\n").errors
    assert [(p.code, p.line) for p in cut] == [("truncated", 5)] and "-1,-1" in cut[0].message


# ---------------------------------------------------------------- properties


@st.composite
def declared_graphs(draw):
    n = draw(st.integers(1, 7))
    ids = [f"t{i}" for i in range(n)]
    edges = draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=12))
    requires: dict[str, list[str]] = {}
    for b, a in edges:
        if a != b and ids[b] not in requires.get(ids[a], []):
            requires.setdefault(ids[a], []).append(ids[b])
    return ids, requires


def _has_cycle(ids, requires) -> bool:
    # Kahn's algorithm: a second, independent way to find out.
    indeg = {i: len(requires.get(i, [])) for i in ids}
    succ = {i: [] for i in ids}
    for a, bs in requires.items():
        for b in bs:
            succ[b].append(a)
    ready = [i for i in ids if indeg[i] == 0]
    seen = 0
    while ready:
        x = ready.pop()
        seen += 1
        for y in succ[x]:
            indeg[y] -= 1
            if indeg[y] == 0:
                ready.append(y)
    return seen < len(ids)


@settings(max_examples=150, deadline=None)
@given(declared_graphs())
def test_check_accepts_acyclic_and_names_a_real_cycle_otherwise(graph):
    ids, requires = graph
    doc = {"parts": ids, "requires": requires}
    result = check_text(json.dumps(doc), fmt="json")
    if _has_cycle(ids, requires):
        assert not result.ok
        cycles = find_cycles(ids, requires)
        assert cycles
        for cycle in cycles:
            assert cycle[0] == cycle[-1]
            for before, after in zip(cycle, cycle[1:]):
                assert before in requires.get(after, [])  # each arrow is a declared constraint
        assert any(p.code == "cycle" and " -> ".join(cycles[0]) in p.message for p in result.errors)
    else:
        assert result.ok, [str(p) for p in result.problems]
