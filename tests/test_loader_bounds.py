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

from opportune.formats import graphfiles, graphs, loader, looks, sequences, validate

MEMORY = 600 << 20   # address space of the child: the Python interpreter itself takes about 64 MB of it
MAX_RSS = 500 << 20  # and at most this much resident
CPU_LIMIT = 60       # seconds of CPU for the whole child (every case it reads)
CPU_EACH = 5.0       # seconds of CPU for one read: refusals take well under one
# Bounds that take a second or more of work to reach (a million GraphML elements, 800,000 DOT
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
        if kind == "plan":
            result = read_plan(path)
            problems = [p.to_dict() for p in result.errors]
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
    """Read ``cases`` ((kind, path) pairs; kind ``plan``, ``looks`` or ``sequences``) in a bounded child.

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
    from opportune.plan import MAX_PARTS, MAX_STRATEGIES, MAX_UNITS

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
