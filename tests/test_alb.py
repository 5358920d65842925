"""SALBP-2013 ``.alb`` files: reading (every bad input on its line), writing, and the graph generator."""

from __future__ import annotations

import io
import itertools
import random
import sys
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import REPO, brute_sequences
from opportune import load_plan
from opportune.engine import Schedule
from opportune.engine.poset import Poset
from opportune.formats import read_plan
from opportune.formats import alb
from opportune.formats.alb import AlbError, check_alb_bytes, order_strength, parse_alb, read_alb, write_alb
from opportune import make_plan

sys.path.insert(0, str(REPO / "benchmarks"))
import gen_precedence  # noqa: E402

# The example of the SALBP-2013 documentation's layout (20 tasks, OS 0,268), with CRLF ends.
EXAMPLE = (
    "<number of tasks>\r\n20\r\n\r\n<cycle time>\r\n1000\r\n\r\n<order strength>\r\n0,268\r\n\r\n\r\n<task times>\r\n"
    + "".join(f"{k} {t}\r\n" for k, t in enumerate(
        [142, 34, 140, 214, 121, 279, 50, 282, 129, 175, 97, 132, 107, 132, 69, 169, 73, 231, 120, 186], 1))
    + "\r\n<precedence relations>\r\n"
    + "".join(f"{p}\r\n" for p in "1,6 2,7 4,8 5,9 6,10 7,11 8,12 10,13 11,13 12,14 12,15 13,16 13,17 13,18 "
                                   "14,20 15,19".split())
    + "\r\n<end>\r\n"
).encode()


def small(pairs="1,2\n1,3", times="1 4\n2 7\n3 2", n="3", end="<end>\n", extra="") -> bytes:
    """A small .alb file, line by line: 1 header, 2 n, 3 header, 4-6 times, 7 header, 8.. pairs."""
    return (f"<number of tasks>\n{n}\n<task times>\n{times}\n<precedence relations>\n{pairs}\n{extra}{end}").encode()


def closure(n: int, pairs) -> set[tuple[int, int]]:
    """Brute-force transitive closure of 1-based pairs: reachability by depth-first search from every task."""
    succ = {i: [b for a, b in pairs if a == i] for i in range(1, n + 1)}
    out = set()
    for start in range(1, n + 1):
        stack, seen = list(succ[start]), set()
        while stack:
            x = stack.pop()
            if x not in seen:
                seen.add(x)
                stack += succ[x]
        out |= {(start, x) for x in seen}
    return out


def errors_of(raw: bytes):
    return check_alb_bytes(raw, file="x.alb").errors


# ---------------------------------------------------------------- reading good files


def test_the_documented_example_reads_with_crlf_and_blank_lines(tmp_path):
    path = tmp_path / "example.ALB"  # suffix in any case
    path.write_bytes(EXAMPLE)
    result = read_plan(path)
    assert result.ok and result.problems == []  # its stated order strength is its own
    plan = result.plan
    assert plan.part_ids == tuple(str(k) for k in range(1, 21))
    assert plan.part("6").install == 279
    graph = read_alb(path)
    assert graph.n == 20 and graph.cycle_time == 1000 and graph.order_strength == 0.268
    assert graph.pairs[0] == (1, 6) and graph.lines[(1, 6)] == 34
    assert load_plan(path).part_ids == plan.part_ids


def test_content_is_detected_without_the_suffix(tmp_path):
    path = tmp_path / "graph.txt"
    path.write_bytes(b"\xef\xbb\xbf" + small())  # with a byte-order mark, too
    plan = load_plan(path)
    assert plan.strategies[0].pairs() == [("1", "2"), ("1", "3")]


def test_unknown_sections_warn_and_are_skipped():
    raw = small(extra="<number of stations>\n4\n")
    result = check_alb_bytes(raw, file="x.alb")
    assert result.ok
    (w,) = result.warnings
    assert w.code == "unknown-section" and w.line == 10 and w.where == "x.alb:10"


def test_sections_in_another_order_and_a_point_decimal():
    raw = b"<task times>\n1 5\n2 6\n<order strength>\n1.000\n<precedence relations>\n1,2\n<number of tasks>\n2\n<end>\n"
    result = check_alb_bytes(raw)
    assert result.ok and result.problems == []


def test_a_wrong_stated_order_strength_is_a_warning_on_its_line():
    raw = EXAMPLE.replace(b"0,268", b"0,5")
    (w,) = check_alb_bytes(raw, file="x.alb").warnings
    assert w.code == "order-strength" and w.line == 8 and "0.268" in w.message


# ---------------------------------------------------------------- reading bad files: error, file and line


BAD = [
    # (what, file bytes, line of the error, words of the message)
    ("no number of tasks", b"<task times>\n1 1\n<precedence relations>\n<end>\n", 1, "no <number of tasks>"),
    ("n not an integer", small(n="3.5"), 2, "whole number"),
    ("n zero", small(n="0"), 2, "whole number ≥ 1"),
    ("n too large", small(n="20001"), 2, "more than this reader accepts (20,000)"),
    ("time not an integer", small(times="1 4\n2 7.5\n3 2"), 5, "time '7.5' is not a whole number"),
    ("negative time", small(times="1 4\n2 -7\n3 2"), 5, "not a whole number ≥ 0"),
    ("task not an integer", small(times="1 4\nb 7\n3 2"), 5, "task number 'b'"),
    ("task times line", small(times="1 4\n2\n3 2"), 5, "is not 'task time'"),
    ("time for task out of range", small(times="1 4\n2 7\n3 2\n4 1"), 7, "task 4 is out of range"),
    ("time given twice", small(times="1 4\n2 7\n2 2"), 6, "task 2 has a second time (first at line 5)"),
    ("missing times", small(times="1 4"), 3, "no time for 2 of the 3 tasks: 2, 3"),
    ("pair not i,j", small(pairs="1,2\n1;3"), 9, "is not 'i,j'"),
    ("pair not integers", small(pairs="1,2\n1,x"), 9, "is not 'i,j'"),
    ("pair out of range", small(pairs="1,2\n1,4"), 9, "names task 4, but tasks are numbered 1..3"),
    ("pair out of range below", small(pairs="0,2"), 8, "names task 0"),
    ("self loop", small(pairs="1,2\n3,3"), 9, "before itself"),
    ("no end", small(end=""), 9, "without `<end>`"),
    ("truncated mid-list", small()[:-12], 8, "without `<end>`"),
    ("cycle time", small(extra="<cycle time>\n12.5\n"), 11, "cycle time must be a whole number"),
    ("order strength", small(extra="<order strength>\n1,5\n"), 11, "order strength must be a number from 0 to 1"),
    ("two values", small(n="3\n4"), 3, "takes one value"),
    ("section twice", small(extra="<task times>\n1 1\n"), 10, "appears twice (first at line 3)"),
    ("text before any section", b"hello\n" + small(), 1, "before any section header"),
]


@pytest.mark.parametrize("what, raw, line, words", BAD, ids=[b[0] for b in BAD])
def test_bad_files_give_an_error_on_the_right_line(what, raw, line, words):
    errors = errors_of(raw)
    assert any(p.line == line and words in p.message and p.file == "x.alb" for p in errors), \
        [str(p) for p in errors]
    assert check_alb_bytes(raw).plan is None
    assert parse_alb(raw)[0] is None


def test_a_cycle_is_an_error_on_a_line_of_the_cycle():
    raw = small(pairs="1,2\n2,3\n3,1", times="1 1\n2 1\n3 1")
    (error,) = errors_of(raw)
    assert error.code == "cycle" and error.line in (8, 9, 10) and "->" in error.message


def test_read_alb_raises_with_every_error(tmp_path):
    path = tmp_path / "bad.alb"
    path.write_bytes(small(pairs="1,9\n2,2", end=""))
    with pytest.raises(AlbError) as info:
        read_alb(path)
    assert [p.line for p in info.value.problems] == [8, 9, 9]  # by line: a bad pair, then no <end> and a bad pair
    assert str(path) in str(info.value)


def test_repeated_pairs_are_one_warning_in_linear_time():
    raw = small(pairs="\n".join(["1,2"] * 100_000 + ["1, 3", "1,3"]))
    check_alb_bytes(small())  # imports out of the timing
    start = time.process_time()
    result = check_alb_bytes(raw, file="x.alb")
    assert time.process_time() - start < 1.0
    assert result.ok
    w = {p.parts: p for p in result.warnings}
    assert w[("1", "2")].line == 9 and "repeated 99,999 times (first at line 8)" in w[("1", "2")].message
    assert "repeated once" in w[("1", "3")].message
    assert result.plan.strategies[0].pairs() == [("1", "2"), ("1", "3")]


def test_too_many_pairs_is_refused(monkeypatch):
    monkeypatch.setattr(alb, "MAX_PAIRS", 5)
    raw = small(pairs="\n".join(f"{a},{b}" for a, b in [(1, 2)] * 6 + [(1, 3)]))
    (error,) = errors_of(raw)
    assert error.code == "limit" and error.line == 13 and "more than 5 precedence relations" in error.message


def test_a_garbage_file_gives_few_problems():
    raw = small(pairs="\n".join(["x"] * 10_000))
    problems = check_alb_bytes(raw).problems
    assert len(problems) == alb.MAX_PER_KIND + 1 and "9950 more problems" in problems[-1].message


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["set", "insert", "delete"]), st.integers(0, 10**6), st.binary(min_size=1, max_size=3)),
                min_size=1, max_size=6))
def test_mutated_files_never_raise(mutations):
    raw = bytearray(EXAMPLE)
    for kind, where, data in mutations:
        k = where % (len(raw) + 1)
        if kind == "set":
            raw[k:k + len(data)] = data
        elif kind == "insert":
            raw[k:k] = data
        else:
            del raw[k:k + len(data)]
    start = time.process_time()
    result = check_alb_bytes(bytes(raw), file="m.alb")
    assert time.process_time() - start < 1.0
    assert result.ok == (result.plan is not None and not result.errors)
    assert all(p.line is None or p.line >= 1 for p in result.problems)


# ---------------------------------------------------------------- writing


@st.composite
def graphs(draw, max_n=10):
    """A random plan: tasks declared in a random order, random arcs along a hidden order, whole install times."""
    n = draw(st.integers(1, max_n))
    order = draw(st.permutations(range(n)))
    ids = [f"t{k}" for k in range(n)]
    requires: dict[str, list[str]] = {}
    for j in range(n):
        for i in range(j):
            if draw(st.integers(0, 3)) == 0:
                requires.setdefault(ids[order[j]], []).append(ids[order[i]])
    times = draw(st.lists(st.integers(0, 1000), min_size=n, max_size=n))
    return make_plan([{"id": ids[k], "install": times[k]} for k in range(n)], requires, name="random")


@settings(max_examples=100, deadline=None)
@given(graphs())
def test_write_then_read_keeps_the_order_and_the_times(plan):
    out = io.StringIO()
    write_alb(plan, out)
    result = check_alb_bytes(out.getvalue().encode(), file="r.alb")
    assert result.ok and result.problems == [], [str(p) for p in result.problems]  # reduced arcs, right strength
    back = result.plan
    assert [p.install for p in back.parts] == [p.install for p in plan.parts]
    n = len(plan.parts)
    before = Poset.from_pairs(n, plan.index_pairs(plan.strategies[0]))
    after = Poset.from_pairs(n, back.index_pairs(back.strategies[0]))
    assert before == after


def test_write_to_a_path_and_a_binary_file(tmp_path):
    plan = make_plan(["a", {"id": "b", "install": 3}, "c"], {"c": ["a", "b"], "b": ["a"]})
    write_alb(plan, tmp_path / "p.alb", cycle_time=9)
    text = (tmp_path / "p.alb").read_text()
    assert "<cycle time>\n9\n" in text and "<order strength>\n1,000\n" in text
    assert "1,2\n2,3\n" in text and "1,3" not in text  # the redundant a -> c is not written
    binary = io.BytesIO()
    write_alb(plan, binary)
    assert binary.getvalue().decode() == text.replace("\n9\n", "\n3\n")  # default cycle time: the longest task


@pytest.mark.parametrize("plan, words", [
    (make_plan(["a", "b"], strategies={"x": {"b": ["a"]}, "y": {"a": ["b"]}}), "2 strategies"),
    (make_plan([{"id": "a", "quantity": 2}, "b"]), "quantity > 1"),
    (make_plan([{"id": "a", "install": 1.5}]), "whole numbers"),
])
def test_plans_the_format_cannot_hold_are_refused(plan, words):
    with pytest.raises(ValueError, match=words):
        write_alb(plan, io.StringIO())


# ---------------------------------------------------------------- order strength


def forward_pairs(n: int, max_size: int, base: int):
    """Random arcs ``(a, b)``, ``a < b``, on ``base .. base + n - 1`` (a DAG by construction)."""
    ends = st.tuples(st.integers(base, base + n - 1), st.integers(base, base + n - 1))
    return st.lists(ends, max_size=max_size).map(lambda ps: [(min(p), max(p)) for p in ps if p[0] != p[1]])


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 9).flatmap(lambda n: st.tuples(st.just(n), forward_pairs(n, 15, 1))))
def test_order_strength_is_the_share_of_ordered_pairs(graph):
    n, pairs = graph
    expected = len(closure(n, pairs)) / (n * (n - 1) / 2) if n > 1 else 0.0
    assert order_strength(n, pairs) == pytest.approx(expected)
    assert gen_precedence.order_strength(n, pairs) == pytest.approx(expected)


@settings(max_examples=100, deadline=None)
@given(st.integers(2, 12).flatmap(lambda n: st.tuples(st.just(n), forward_pairs(n, 20, 0))))
def test_the_generators_incremental_closure_matches_a_brute_force(graph):
    n, arcs = graph
    g = gen_precedence.Closure(n)
    for i, j in arcs:
        if not g.ordered(i, j):
            g.add(i, j, g.gain(i, j))
    expected = closure(n, [(a + 1, b + 1) for a, b in arcs])
    assert g.comparable == len(expected)
    assert {(a + 1, b + 1) for a in range(n) for b in range(n) if g.ordered(a, b)} == expected


# ---------------------------------------------------------------- the generator


CASES = [(40, 0.3, "chain"), (60, 0.6, "bottleneck"), (80, 0.9, "mixed"), (50, 0.2, "mixed"), (70, 0.75, "chain")]


@pytest.mark.parametrize("n, target, structure", CASES)
def test_generated_graphs_are_reduced_dags_near_the_target(n, target, structure):
    arcs, times = gen_precedence.generate(n, target, structure, seed=3)
    assert len(times) == n and all(1 <= t <= 100 for t in times)
    assert all(1 <= a < b <= n for a, b in arcs)  # numbered in a topological order: acyclic
    poset = Poset.from_pairs(n, [(a - 1, b - 1) for a, b in arcs])
    assert [(a + 1, b + 1) for a, b in poset.cover_pairs()] == arcs  # transitively reduced, sorted
    assert abs(order_strength(n, arcs) - target) <= 0.03
    assert gen_precedence.generate(n, target, structure, seed=3) == (arcs, times)  # deterministic
    assert gen_precedence.generate(n, target, structure, seed=4) != (arcs, times)


def test_structures_have_their_shape():
    def degrees(arcs):
        ins, outs = [0] * 301, [0] * 301
        for a, b in arcs:
            outs[a] += 1
            ins[b] += 1
        return ins, outs

    ins, outs = degrees(gen_precedence.generate(300, 0.6, "chain", seed=1)[0])
    assert max(ins) <= 4 and sum(1 for i, o in zip(ins, outs) if i <= 1 and o <= 1) >= 0.8 * 300
    ins, outs = degrees(gen_precedence.generate(300, 0.6, "bottleneck", seed=1)[0])
    assert max(ins) >= 10 and max(outs) >= 10  # bottlenecks join several branches


def test_a_tiny_generated_file_loads_and_counts_like_a_brute_force(tmp_path):
    for seed, target in itertools.product(range(3), (0.3, 0.6)):
        arcs, times = gen_precedence.generate(7, target, "mixed", seed=seed)
        path = tmp_path / f"tiny-{seed}-{target}.alb"
        path.write_text(alb.graph_text(times, arcs))
        plan = load_plan(path)
        assert [p.install for p in plan.parts] == times
        assert Schedule(plan).count() == len(brute_sequences(plan))


def test_the_command_line_writes_one_file_or_the_set(tmp_path, capsys):
    one = tmp_path / "one.alb"
    assert gen_precedence.main(["--n", "40", "--os", "0.5", "--structure", "chain", "--seed", "2", "-o", str(one)]) == 0
    graph = read_alb(one)
    assert graph.n == 40 and abs(graph.order_strength - 0.5) <= 0.03
    assert gen_precedence.main(["--out-dir", str(tmp_path / "set"), "--n", "30", "40", "--os", "0.2", "0.9"]) == 0
    names = sorted(p.name for p in (tmp_path / "set").iterdir())
    assert names == ["gen-n30-os0.2.alb", "gen-n30-os0.9.alb", "gen-n40-os0.2.alb", "gen-n40-os0.9.alb"]
    assert all(read_plan(tmp_path / "set" / name).ok for name in names)
    assert "order strength" in capsys.readouterr().out


def test_random_stream_is_not_shared():
    # generate() seeds its own generators: the global random state neither matters nor changes.
    random.seed(1)
    state = random.getstate()
    first = gen_precedence.generate(30, 0.5, seed=9)
    random.seed(2)
    assert gen_precedence.generate(30, 0.5, seed=9) == first
    random.setstate(state)
