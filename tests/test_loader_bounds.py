"""Every loader refuses oversized and hostile input by its stated bound, in bounded memory and time.

Each input is read in a child process under ``resource.setrlimit``: RLIMIT_AS (address space,
:data:`MEMORY`) and RLIMIT_CPU (:data:`CPU_LIMIT` seconds).  Going past either kills the child (or
raises MemoryError in it), so a passing test proves the bound without measuring wall-clock time,
which other processes on the machine would skew.  The CPU time each read took (``process_time``
in the child) is checked against :data:`CPU_EACH`, the promise of the loaders: any file the
command line accepts is refused or loaded within 5 s and 500 MB.  Inputs sit just past the bounds
(one item more), except the two attacks of the issue that found the gap: a 32 MiB JSON list and
its YAML twin.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import textwrap

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune.formats import graphfiles, graphs, loader, looks, sequences, validate

MEMORY = 600 << 20   # address space of the child: the Python interpreter itself takes about 64 MB of it
MAX_RSS = 500 << 20  # and at most this much resident
CPU_LIMIT = 60       # seconds of CPU for the whole child (every case it reads)
CPU_EACH = 5.0       # seconds of CPU for one read: refusals take well under one
# Bounds that take a second or more of work to reach (800,000 GraphML elements, 800,000 DOT
# tokens or 120,000 DOT edges, millions of ids in looks and sequences) are lowered to this in the
# child: the test shows the mechanism and its message; reaching the real values costs 1-2 s each.
LOW = 10_000

_CHILD = textwrap.dedent("""
    import json, resource, sys, time
    import importlib
    memory, cpu, cases, bounds = json.loads(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))
    for module, values in bounds.items():
        for name, value in values.items():
            setattr(importlib.import_module(module), name, value)
    from opportune.formats.loader import read_plan
    from opportune.formats.looks import LooksError, read_looks
    from opportune.formats.sequences import SequenceError, read_sequences
    def peak_reset():
        # the peak resident size per case (Linux: writing 5 to clear_refs resets VmHWM), so that each
        # file is held to the bound alone, as the command line reads one file per process
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
        except OSError:
            pass

    def peak():
        try:
            with open("/proc/self/status") as f:
                for line in f:
                    if line.startswith("VmHWM:"):
                        return int(line.split()[1]) * 1024
        except OSError:
            pass
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

    out = []
    for kind, path in cases:
        peak_reset()
        start = time.process_time()
        if kind in ("plan", "check"):
            result = read_plan(path)
            problems = [p.to_dict() for p in result.errors]
            if kind == "check" and result.ok:   # what `opportune check` does besides printing
                from opportune.formats.summary import summarize
                summarize(result.plan)
        elif kind == "results":
            from opportune.formats.results import ResultsError, read_recorded_study
            try:
                read_recorded_study(path)
                problems = []
            except ResultsError as exc:
                problems = [{"code": "limit", "message": str(exc)}]
        else:
            problems = []
            try:
                (read_looks if kind == "looks" else read_sequences)(path)
            except (LooksError, SequenceError) as exc:
                problems = [exc.problem.to_dict()]
        out.append({"problems": problems, "cpu": time.process_time() - start, "rss": peak()})
    out.append({"maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024})
    print(json.dumps(out))
""")


def read_bounded(cases, stdin=None, bounds=None):
    """Read ``cases`` ((kind, path) pairs; kind ``plan``, ``check`` (a plan and its summary), ``results``
    (a results.json for ``simulate --from``), ``looks`` or ``sequences``) in a bounded child.

    ``bounds`` (``{module: {NAME: value}}``) lowers bounds in the child, for those whose real value
    takes a second or more of work to reach (see :data:`LOW`).
    Returns one dict per case: ``problems`` (the errors, as ``Problem.to_dict()``) and ``cpu``.
    """
    env = dict(os.environ, PYTHONHASHSEED="0")
    with open(stdin, "rb") if stdin else open(os.devnull, "rb") as feed:
        proc = subprocess.run([sys.executable, "-c", _CHILD, json.dumps([MEMORY, CPU_LIMIT, cases, bounds or {}])],
                              stdin=feed, capture_output=True, text=True, env=env, check=False)
    assert proc.returncode == 0, f"the child failed (killed past a limit?): {proc.returncode}\n{proc.stderr[-3000:]}"
    *results, usage = json.loads(proc.stdout)
    for case, result in zip(cases, results):
        assert result["rss"] <= MAX_RSS, (case, f"{result['rss'] / 2**20:.0f} MB resident")
        assert result["cpu"] <= CPU_EACH, (case, result["cpu"])
    return results


def refused(result, path, *words, line=True):
    """The refusal of a read (its first "limit" error): it names the file, the line (if ``line``) and ``words``."""
    assert result["problems"], "accepted"
    p = next((p for p in result["problems"] if p["code"] == "limit"), result["problems"][0])
    assert p["code"] == "limit", p
    assert os.path.basename(p["file"] or "") == os.path.basename(str(path)), p
    assert (p["line"] is not None) == line, p
    for word in words:
        assert word in p["message"], (word, p)
    assert p["hint"], p
    return p


def n(limit: int) -> str:
    """A bound as the messages write it."""
    return f"{limit:,}"


# ---------------------------------------------------------------- YAML and JSON plans


def test_plan_documents_over_their_bounds_are_refused_in_bounded_memory(tmp_path):
    past = loader.MAX_VALUES + 1
    files = {
        # the attacks: 32 MiB holding one list of 8.4 million items
        "huge.json": '{"parts": [' + ",".join(["1"] * 8_400_000) + "]}",
        "huge.yaml": "parts: [" + ",".join(["1"] * 8_400_000) + "]\n",
        # one value past the bound, as a flow list, a block list and JSON keys
        "flow.yaml": "name: x\nparts: [" + ", ".join(f"p{i}" for i in range(past)) + "]\n",
        "block.yaml": "parts:\n" + "".join(f"- p{i}\n" for i in range(past)),
        "keys.json": '{"parts": ["a"],\n "requires": {' + ",\n".join(f'"k{i}": "a"' for i in range(past)) + "}}",
        # nesting 100,000 deep (far past Python's recursion limit), and a string longer than any id or name
        "deep.json": '{"parts": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "deep.yaml": "parts: " + "[" * 100_000 + "]" * 100_000 + "\n",
        "text.yaml": "name: x\nparts: [" + "a" * (validate.MAX_TEXT + 1) + "]\n",
        # six million escapes in one string: a regular expression that saves its state at each
        # repeat would take 700 MB to skip it (the pre-scan counts separators outside strings)
        "escapes.json": '{"parts": ["' + "\\\\" * 6_000_000 + '"], "x": [' + "1," * past + "1]}",
        # billion laughs: 352 bytes that would expand to 387 million values
        "laughs.yaml": "\n".join(['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
                                 + [f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]" for p, c in zip("abcdefgh", "bcdefghi")]
                                 + ["parts: *i"]) + "\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert (tmp_path / "huge.json").stat().st_size <= loader.MAX_FILE_BYTES
    results = dict(zip(files, read_bounded([("plan", str(tmp_path / name)) for name in files])))
    for name in ("huge.json", "huge.yaml", "flow.yaml", "block.yaml", "keys.json", "escapes.json"):
        p = refused(results[name], name, f"more than {n(loader.MAX_VALUES)} values", f"at most {n(loader.MAX_VALUES)}")
        assert "alias" not in p["message"], p  # the JSON was refused with a message about YAML aliases
    # the line is where the first value past the bound stands
    # block.yaml: the document, `parts` and the list are values 1-3, item i (from 0) value 4 + i on line 2 + i
    assert results["block.yaml"]["problems"][0]["line"] == 2 + (past - 4)
    # keys.json: 6 values before `requires`' mapping's first key; key i (from 0) is value 7 + 2i, on line 2 + i
    assert results["keys.json"]["problems"][0]["line"] == 2 + (past - 7) // 2
    for name in ("deep.json", "deep.yaml"):
        refused(results[name], name, f"{loader.MAX_DEPTH} levels")
    refused(results["text.yaml"], "text.yaml", f"at most {n(validate.MAX_TEXT)}")
    refused(results["laughs.yaml"], "laughs.yaml", "alias")


def test_a_plan_over_the_byte_bound_on_standard_input_is_refused_unread(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_bytes(b"parts: [a]\n" + b"#" * loader.MAX_FILE_BYTES)
    (result,) = read_bounded([("plan", "-")], stdin=path)
    refused(result, "<stdin>", f"larger than {n(loader.MAX_FILE_BYTES)} bytes", line=False)


# ---------------------------------------------------------------- graph files


def test_graph_files_over_their_bounds_are_refused_in_bounded_memory(tmp_path):
    tasks, pairs = graphs.MAX_TASKS + 1, graphs.MAX_PAIRS + 1
    header = "<number of tasks>\n3\n<task times>\n1 1\n2 1\n3 1\n<precedence relations>\n"
    files = {
        "nodes.dot": "digraph g {\n" + "".join(f"n{i};\n" for i in range(tasks)) + "}\n",
        "edges.dot": "digraph g {\n" + "a -> b;\n" * (LOW // 10 + 1) + "}\n",  # MAX_PAIRS lowered to LOW / 10
        "tokens.dot": "digraph g {\n" + "a = b;\n" * (LOW // 3 + 1) + "}\n",  # MAX_TOKENS lowered to LOW
        "nodes.graphml": '<graphml><graph id="g">\n' + "".join(f'<node id="n{i}"/>\n' for i in range(tasks))
                         + "</graph></graphml>\n",
        "edges.graphml": '<graphml><graph id="g">\n' + '<edge source="a" target="b"/>\n' * pairs + "</graph></graphml>\n",
        "elements.graphml": '<graphml><graph id="g">\n' + "<x/>\n" * LOW + "</graph></graphml>\n",  # lowered too
        "deep.graphml": "<graphml>" + "<g>" * 1_000_000 + "</g>" * 1_000_000 + "</graphml>\n",
        "text.dot": 'digraph g {\n a [label="' + "\\\\" * 6_000_000 + '"];\n}\n',  # six million escapes
        "text.graphml": '<graphml><graph id="g"><node id="a"><data key="name">' + "x" * (validate.MAX_TEXT + 1)
                        + "</data></node></graph></graphml>\n",
        "pairs.alb": header + "1,2\n" * pairs + "<end>\n",
        "lines.alb": header + "\n" * graphs.MAX_LINES + "<end>\n",
        "wide.alb": "<number of tasks>\n3\n<task times>\n" + "1 " * graphs.MAX_LINE_CHARS + "\n<end>\n",
        "pairs.IN2": "3\n1\n1\n1\n" + "1,2\n" * pairs + "-1,-1\n",
        "lines.IN2": "3\n1\n1\n1\n" + "1,2\r\n" * (graphs.MAX_LINES + 1) + "-1,-1\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    low = ("tokens.dot", "elements.graphml", "edges.dot")
    lowered = {"opportune.formats.graphfiles": {"MAX_TOKENS": LOW, "MAX_ELEMENTS": LOW, "MAX_PAIRS": LOW // 10}}
    real = [name for name in files if name not in low]
    results = dict(zip(real, read_bounded([("plan", str(tmp_path / name)) for name in real])))
    results.update(zip(low, read_bounded([("plan", str(tmp_path / name)) for name in low], bounds=lowered)))
    for name, words in {
        "nodes.dot": (f"more than {n(graphs.MAX_TASKS)} nodes",),
        "edges.dot": (f"more than {n(LOW // 10)} edges",),
        "tokens.dot": (f"more than {n(LOW)} tokens",),
        "nodes.graphml": (f"more than {n(graphs.MAX_TASKS)} nodes",),
        "edges.graphml": (f"more than {n(graphs.MAX_PAIRS)} <edge>",),
        "elements.graphml": (f"more than {n(LOW)} elements",),
        "deep.graphml": (f"more than {loader.MAX_DEPTH} levels",),
        "text.graphml": (f"at most {n(validate.MAX_TEXT)}",),
        "text.dot": (f"at most {n(validate.MAX_TEXT)}",),
        "pairs.alb": (f"more than {n(graphs.MAX_PAIRS)} precedence",),
        "lines.alb": (f"at most {n(graphs.MAX_LINES)} lines",),
        "wide.alb": (f"at most {n(graphs.MAX_LINE_CHARS)}",),
        "pairs.IN2": (f"more than {n(graphs.MAX_PAIRS)} precedence",),
        "lines.IN2": (f"at most {n(graphs.MAX_LINES)} lines",),
    }.items():
        refused(results[name], name, *words)
    assert results["nodes.dot"]["problems"][0]["line"] == tasks + 1
    assert results["edges.graphml"]["problems"][0]["line"] == pairs + 1
    assert results["lines.IN2"]["problems"][0]["line"] == graphs.MAX_LINES + 1


# ---------------------------------------------------------------- looks and sequences files


def test_looks_and_sequences_files_over_their_bounds_are_refused_in_bounded_memory(tmp_path):
    files = {
        "lines.looks": ("looks", "#\n" * (looks.MAX_LOOK_LINES + 1)),
        "parts.looks": ("looks", "ab cd ef gh\n" * (LOW // 4 + 1)),  # MAX_LOOK_PARTS lowered to LOW
        "wide.looks": ("looks", "a " * looks.MAX_LOOK_LINE_CHARS + "\n"),
        "many.json": ("looks", "[" + ",".join(['["ab"]'] * (looks.MAX_LOOKS // 2 + LOW)) + "]"),
        "lines.seq": ("sequences", "#\n" * (sequences.MAX_SEQUENCE_LINES + 1)),
        "items.seq": ("sequences", (" ".join(f"p{i}" for i in range(100)) + "\n") * (LOW // 100 + 1)),  # lowered
        "wide.seq": ("sequences", "a " * sequences.MAX_SEQUENCE_LINE_CHARS + "\n"),
    }
    for name, (_, text) in files.items():
        (tmp_path / name).write_text(text)
    lowered = {"opportune.formats.looks": {"MAX_LOOK_PARTS": LOW},
               "opportune.formats.sequences": {"MAX_SEQUENCE_ITEMS": LOW}}
    results = dict(zip(files, read_bounded([(kind, str(tmp_path / name)) for name, (kind, _) in files.items()],
                                           bounds=lowered)))
    refused(results["lines.looks"], "lines.looks", f"more than {n(looks.MAX_LOOK_LINES)} lines")
    refused(results["parts.looks"], "parts.looks", f"more than {n(LOW)} part ids")
    refused(results["wide.looks"], "wide.looks", f"at most {n(looks.MAX_LOOK_LINE_CHARS)}")
    refused(results["many.json"], "many.json", f"more than {n(1 + looks.MAX_LOOKS + LOW)} values")
    refused(results["lines.seq"], "lines.seq", f"more than {n(sequences.MAX_SEQUENCE_LINES)} lines")
    refused(results["items.seq"], "items.seq", f"more than {n(LOW)} installations")
    refused(results["wide.seq"], "wide.seq", f"at most {n(sequences.MAX_SEQUENCE_LINE_CHARS)}")


# ---------------------------------------------------------------- what must still load


def test_a_plan_of_10000_parts_still_loads_under_the_same_limits(tmp_path):
    rng = random.Random(7)
    ids = [f"p{i}" for i in range(10_000)]
    requires = {ids[i]: sorted({ids[rng.randrange(max(0, i - 40), i)] for _ in range(2)}) for i in range(1, 10_000)}
    (tmp_path / "big.yaml").write_text(
        "name: big\nparts: [" + ", ".join(ids) + "]\nrequires:\n"
        + "".join(f"  {k}: [{', '.join(v)}]\n" for k, v in requires.items()))
    (tmp_path / "big.json").write_text(json.dumps({"name": "big", "parts": ids, "requires": requires}, indent=1))
    arcs = sorted({(a + 1, b + 1) for b in range(1, 10_000) for a in {rng.randrange(max(0, b - 40), b)}})
    (tmp_path / "big.alb").write_text("<number of tasks>\n10000\n<task times>\n"
                                      + "".join(f"{t} {1 + t % 9}\n" for t in range(1, 10_001))
                                      + "<precedence relations>\n" + "".join(f"{a},{b}\n" for a, b in arcs) + "<end>\n")
    names = ["big.yaml", "big.json", "big.alb"]
    for result in read_bounded([("plan", str(tmp_path / name)) for name in names]):
        assert result["problems"] == []


def test_bounds_are_consistent_with_the_plan_limits():
    from opportune.planning.plan import MAX_PARTS, MAX_STRATEGIES, MAX_UNITS

    # a plan of the largest size has room for a few constraints per part in every format
    assert loader.MAX_VALUES >= 10 * MAX_PARTS and graphs.MAX_PAIRS >= 10 * MAX_UNITS
    assert graphs.MAX_TASKS >= MAX_UNITS and graphs.MAX_LINES >= graphs.MAX_TASKS + graphs.MAX_PAIRS
    assert graphfiles.MAX_TOKENS >= 4 * graphs.MAX_PAIRS
    assert graphfiles.MAX_ELEMENTS >= MAX_UNITS * 2 + graphs.MAX_PAIRS  # a node and its data, every edge
    assert loader.MAX_ALIAS_VALUES < loader.MAX_VALUES and MAX_STRATEGIES <= loader.MAX_DEPTH
    assert sequences.MAX_SEQUENCE_ITEMS >= 100 * MAX_UNITS and looks.MAX_LOOK_PARTS >= looks.MAX_LOOKS


def test_redundant_constraints_past_the_cap_are_counted_exactly():
    # a chain p0 -> p1 -> ... -> p59 that also states p_i before p_j for every j >= i + 2: each of those
    # is implied by the chain, 58 * 59 / 2 = 1,711 of them, counted by hand
    k = 60
    requires = {f"p{j}": [f"p{i}" for i in range(j)] for j in range(1, k)}
    result = loader.check_text(json.dumps({"parts": [f"p{i}" for i in range(k)], "requires": requires}), fmt="json")
    redundant = [p for p in result.warnings if p.code == "redundant"]
    assert result.ok and len(redundant) == validate.MAX_PER_KIND + 1
    expected = (k - 2) * (k - 1) // 2
    assert f"and {expected - validate.MAX_PER_KIND:,} more problems" in redundant[-1].message
    assert all(p.line is not None for p in redundant)


@pytest.mark.parametrize("libyaml", [True, False])
def test_yaml_bounds_hold_with_and_without_libyaml(monkeypatch, libyaml):
    import yaml

    if libyaml and not getattr(yaml, "__with_libyaml__", False):
        pytest.skip("PyYAML without libyaml")
    monkeypatch.setattr(yaml, "__with_libyaml__", libyaml)
    monkeypatch.setattr(loader, "MAX_VALUES", 50)
    monkeypatch.setattr(loader, "MAX_DEPTH", 10)
    text = "name: x\nparts:\n" + "".join(f"- p{i}\n" for i in range(30)) + "requires: {p1: [p0], p2: [p0, p1]}\n"
    doc = loader.parse_yaml(text, "ok.yaml")
    assert not doc.problems and doc.data == yaml.safe_load(text) and doc.line(("parts", 29)) == 32
    (p,) = loader.parse_yaml("parts:\n" + "".join(f"- p{i}\n" for i in range(60)), "many.yaml").problems
    assert p.code == "limit" and "more than 50 values" in p.message and p.line == 2 + 50 - 3
    deep = "parts: " + "[" * (loader.MAX_DEPTH + 1) + "]" * (loader.MAX_DEPTH + 1) + "\n"
    (p,) = loader.parse_yaml(deep, "deep.yaml").problems
    assert p.code == "limit" and f"{loader.MAX_DEPTH} levels" in p.message and p.line == 1
    (p,) = loader.parse_yaml("a: &a [x, x, x, x, x, x, x, x, x, x]\nparts: [*a, *a, *a, *a, *a]\n", "a.yaml").problems
    assert p.code == "limit" and "more than 50" in p.message


# ---------------------------------------------------------------- the loaders' corners, accepted

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.fixture(scope="module")
def strategies_at_the_bound(tmp_path_factory):
    """The plan of the most strategies (64) over the most parts (10,000) at the value bound, as JSON
    (written once: benchmarks/bench_loaders.py sweeps every corner, in YAML too)."""
    from bench_loaders import strategies_at_value_bound

    doc = strategies_at_value_bound()
    d = tmp_path_factory.mktemp("corner")
    (d / "s64.json").write_text(json.dumps(doc))
    return doc, d


def test_most_strategies_over_most_parts_are_checked_within_the_promise(strategies_at_the_bound):
    # 64 strategies of 10,000 parts at 150,000 values took 6.65 s of CPU to check (64 closures of
    # 10,000-bit sets, then again for the summary): each strategy's order is now built once, on the
    # parts it constrains, and compared with the others by its covers.  read_bounded holds each file
    # (read, checked and summarised, as `opportune check` does) to 5 s of CPU and 500 MB.
    doc, d = strategies_at_the_bound
    assert loader.json_values_past(json.dumps(doc), loader.MAX_VALUES) is None
    assert loader.json_values_past(json.dumps(doc), loader.MAX_VALUES - 1) is not None   # exactly at the bound
    (result,) = read_bounded([("check", str(d / "s64.json"))])
    assert result["problems"] == []


def _closure_contains(stricter, looser) -> bool:
    """The definition: every comparable pair of ``looser`` is one of ``stricter`` (full-size posets)."""
    return all((looser.below[k] & ~stricter.below[k]) == 0 for k in range(stricter.n))


@settings(max_examples=80, deadline=None)
@given(st.integers(2, 9).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), min_size=1, max_size=12),
                         min_size=2, max_size=3))))
def test_strategy_orders_agree_with_the_closure_on_the_whole_plan(case):
    from opportune.engine.poset import CycleError, Poset
    from opportune.planning.orders import StrategyOrder

    n, strategies = case
    orders, posets = [], []
    for pairs in strategies:
        pairs = [(a, b) for a, b in pairs if a != b] or [(0, 1)]
        try:
            poset = Poset.from_pairs(n, pairs)
        except CycleError:
            with pytest.raises(CycleError) as info:
                StrategyOrder(pairs)
            cycle = info.value.cycle       # a real cycle of the given pairs
            assert cycle[0] == cycle[-1] and all((a, b) in pairs for a, b in zip(cycle, cycle[1:]))
            continue
        order = StrategyOrder(pairs)
        assert order.cover_pairs() == sorted(poset.cover_pairs())
        assert order.implied == sum(bin(m).count("1") for m in poset.below)
        assert all(order.less(a, b) == poset.less(a, b) for a in range(n) for b in range(n))
        orders.append(order)
        posets.append(poset)
    for i in range(len(orders)):
        for j in range(len(orders)):
            assert orders[i].contains(orders[j]) == _closure_contains(posets[i], posets[j])
            assert (orders[i].covers() == orders[j].covers()) == (posets[i] == posets[j])


# characters the YAML pass reads as JSON does: of the basic plane (it cannot read the escapes of
# the others), printable, and no line breaks of YAML's own (U+0085, U+2028 and U+2029 are not in JSON)
_PRINTABLE = st.characters(max_codepoint=0xFFFF, blacklist_categories=("Cs", "Cc", "Cf", "Cn", "Co", "Zl", "Zp"))
_json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(_PRINTABLE, max_size=6),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.text(_PRINTABLE, max_size=4),
                      inner, max_size=4),
    max_leaves=25)


@settings(max_examples=80, deadline=None)
@given(_json_values, st.sampled_from([None, 0, 1, 2]), st.booleans())
def test_the_lines_of_json_are_those_of_the_yaml_pass(value, indent, ascii_only):
    # JSON lines come from one pass over the tokens instead of the YAML pass (2.3 s at the value bound)
    text = json.dumps(value, indent=indent, ensure_ascii=ascii_only)
    yaml_lines = {k: v for k, v in loader.parse_yaml(text).lines.items() if "<key>" not in k}
    assert loader.json_lines(text) == yaml_lines


def _composed(text: str):
    """parse_yaml by its composer's path (the pre-scan, the composer, the build), for comparison."""
    original = loader._build_from_events

    def fall_back(*_args):
        raise loader._Fallback

    loader._build_from_events = fall_back
    try:
        return loader.parse_yaml(text, "x.yaml")
    finally:
        loader._build_from_events = original


def _same_reading(text: str) -> None:
    a, b = loader.parse_yaml(text, "x.yaml"), _composed(text)
    assert repr(a.data) == repr(b.data), text
    assert {k: v for k, v in a.lines.items() if "<key>" not in k} == \
        {k: v for k, v in b.lines.items() if "<key>" not in k}, text
    assert [p.to_dict() for p in a.problems] == [p.to_dict() for p in b.problems], text


@settings(max_examples=60, deadline=None)
@given(_json_values, st.sampled_from([None, True, False]))
def test_yaml_read_from_events_is_what_the_composer_reads(value, flow):
    import yaml

    if not getattr(yaml, "__with_libyaml__", False):
        pytest.skip("PyYAML without libyaml: the composer's path is the only one")
    _same_reading(yaml.safe_dump(value, default_flow_style=flow, allow_unicode=True))


@pytest.mark.parametrize("text", [
    "", "# only a comment\n", "---\n", "~\n", "a: 1\na: 2\n", "a: {b: 1, b: [1, 2]}\nc: 3\n",
    "a: [1, 2.5, true, null, '3', 0x1f, 2020-01-01, .inf]\n", "---\na: 1\n---\nb: 2\n", "a: !!int x\n",
    "? [a]\n: 1\n", "a: &x 1\nb: *x\n", "<<: {a: 1}\n", "a: !!set {x, y}\n", "12: [3]\n", "a: 1\n  b: 2\n",
    "a: [\n", "a:\n  - b: 1\n    b: 2\n  - [x, {y: z}]\n", "a: 1\na: {b: [1, 2, {c: d}]}\nx: 1\n",
    "x: " + "[" * 70 + "]" * 70 + "\n", "p: [" + ",".join(["1"] * 60) + "]\n", "p: " + "9" * 5000 + "\n",
])
@pytest.mark.parametrize("bounds", [(None, None), (50, 10)])
def test_yaml_read_from_events_keeps_every_finding_and_bound(monkeypatch, text, bounds):
    import yaml

    if not getattr(yaml, "__with_libyaml__", False):
        pytest.skip("PyYAML without libyaml: the composer's path is the only one")
    if bounds[0]:
        monkeypatch.setattr(loader, "MAX_VALUES", bounds[0])
        monkeypatch.setattr(loader, "MAX_DEPTH", bounds[1])
    _same_reading(text)


def test_an_in2_file_with_the_most_pairs_is_read(monkeypatch, tmp_path):
    # the end marker after MAX_PAIRS pairs was counted as one pair more, and such a file refused
    from opportune.formats import salbp

    monkeypatch.setattr(salbp, "MAX_PAIRS", 5)
    head = "6\n" + "1\n" * 6
    at = tmp_path / "at.IN2"
    at.write_text(head + "".join(f"{i},{i + 1}\n" for i in range(1, 6)) + "-1,-1\n")
    past = tmp_path / "past.IN2"
    past.write_text(head + "".join(f"{i},{i + 1}\n" for i in range(1, 6)) + "1,6\n-1,-1\n")
    assert loader.read_plan(at).ok
    (p,) = loader.read_plan(past).errors
    assert p.code == "limit" and "more than 5 precedence lines" in p.message and p.line == 13


def test_unknown_ids_past_the_cap_are_counted_not_built():
    k = 300
    text = json.dumps({"parts": ["a"], "requires": {"a": [f"u{i}" for i in range(k)]}})
    result = loader.check_text(text, fmt="json")
    unknown = [p for p in result.errors if p.code == "unknown-part"]
    assert len(unknown) == validate.MAX_PER_KIND + 1
    assert f"and {k - validate.MAX_PER_KIND:,} more problems" in unknown[-1].message
    assert "did you mean 'a'?" not in unknown[0].hint or unknown[0].parts == ("u0",)


# ---------------------------------------------------------------- results files (simulate --from)


def test_results_files_are_refused_by_size_and_shape_before_they_are_parsed(tmp_path):
    from opportune.formats.results import MAX_RESULTS_BYTES, MAX_RESULTS_VALUES

    files = {
        "big.json": b"{" + b" " * MAX_RESULTS_BYTES + b"}",
        "values.json": b"[" + b"1," * MAX_RESULTS_VALUES + b"1]",
        "deep.json": b"[" * 100_000 + b"]" * 100_000,
        "strategies.json": json.dumps({"provenance": {"study": {"strategies": ["random"] * 65},
                                                      "plan": {}}}).encode(),
        "latin1.json": b'{"a": "\xe9"}',
    }
    for name, raw in files.items():
        (tmp_path / name).write_bytes(raw)
    cases = [("results", str(tmp_path / name)) for name in files] + [("results", "/dev/zero")]
    results = dict(zip([*files, "zero"], read_bounded(cases)))
    for name, words in {"big.json": f"larger than {MAX_RESULTS_BYTES:,} bytes",
                        "values.json": f"more than {MAX_RESULTS_VALUES:,} values",
                        "deep.json": "nested more than", "strategies.json": "65 strategies",
                        "latin1.json": "not UTF-8", "zero": "larger than"}.items():
        (p,) = results[name]["problems"]
        assert words in p["message"], (name, p)
        assert ("big.json" if name == "zero" else name) in p["message"] or name == "zero", p
        assert "give the results.json" in p["message"] or "rerun" in p["message"], p


def test_a_results_file_of_a_plan_at_the_bounds_is_read_within_the_promise(strategies_at_the_bound, tmp_path):
    from opportune.formats.results import MAX_RESULTS_VALUES, read_recorded_study

    doc, _ = strategies_at_the_bound
    # the plan at the loaders' value bound, and a summary that brings the file to its own bound
    results = {"strategies": {"x": []}, "provenance": {"study": {"strategies": ["random"]}, "plan": doc}}
    counted = 1 + sum(json.dumps(results).count(c) for c in ",:[{")   # as json_values_past counts
    results["strategies"]["x"] = [1] * (MAX_RESULTS_VALUES - counted + 1)   # k items add k - 1 commas
    text = json.dumps(results)
    assert loader.json_values_past(text, MAX_RESULTS_VALUES) is None
    assert loader.json_values_past(text, MAX_RESULTS_VALUES - 1) is not None
    path = tmp_path / "results.json"
    path.write_text(text)
    (result,) = read_bounded([("results", str(path))])
    assert result["problems"] == []   # (read in 0.8 s of CPU time and 75 MB when measured)
    small = tmp_path / "small.json"
    small.write_text(json.dumps({"provenance": {"study": {"strategies": ["random"]}, "plan": {"parts": ["a"]}}}))
    assert read_recorded_study(small)["plan"] == {"parts": ["a"]}


def test_a_files_suffix_is_read_as_pathlib_reads_it():
    # the loader reads suffixes without pathlib (a count's start-up): every name of up to 7
    # characters over these letters gets Path.suffix's answer
    import itertools
    from pathlib import Path

    from opportune.formats.documents import file_suffix as _suffix

    names = ("".join(t) for n in range(1, 8) for t in itertools.product("a./Y", repeat=n))
    assert [n for n in names if _suffix(n) != Path(n).suffix.lower()] == []
