"""Every bound of the plan loaders at its corner: CPU time and peak memory of `opportune check`.

The promise: any file the command line accepts is refused or loaded within 5 s of CPU time and
500 MB.  This writes, for each bound, the largest file the loaders accept (at the bound) and one
just past it, runs ``python -m opportune check FILE --json`` on each in a child process (the whole
command: start-up, reading, checking, the summary it prints), and prints a table of corner, file
size, CPU seconds (user + system of the child, from ``os.wait4``: what other processes on the machine
do does not count), peak resident MB (the child's VmHWM) and the answer.

    python benchmarks/bench_loaders.py                 # every corner (about a minute)
    python benchmarks/bench_loaders.py --only s64      # the corners whose name contains s64
    python benchmarks/bench_loaders.py --count         # also `count --time-limit 5` on the accepted plans

Exit status 1 when a corner breaks the promise (over 5 s CPU or 500 MB) or gets the wrong answer.
The generators are importable (``corners()``): tests/test_loader_bounds.py reads some of them.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CPU_BOUND = 5.0          # seconds of CPU per command
RSS_BOUND = 500 << 20    # bytes resident


def _limits():
    from opportune.planning import plan
    from opportune.formats import graphfiles, graphs, loader, validate

    return loader, graphs, graphfiles, validate, plan


def _dag_requires(ids: list[str], values: int, rng: random.Random, *, window: int = 40,
                  per_key: int = 4) -> dict[str, list[str]]:
    """Constraints ``{after: [befores]}`` over ``ids`` (each before declared earlier, within ``window``)
    using exactly ``values`` document values (a key, its list and its items: 2 + items each)."""
    req: dict[str, list[str]] = {}
    keys = rng.sample(range(1, len(ids)), min(len(ids) - 1, values // 3 + 1))
    k = 0
    while values >= 3 and k < len(keys):
        a = keys[k]
        k += 1
        m = min(per_key, values - 2, a)
        befores = sorted({rng.randrange(max(0, a - window), a) for _ in range(m * 2)})[:m]
        if not befores:
            continue
        req[ids[a]] = [ids[b] for b in befores]
        values -= 2 + len(befores)
    return req


def _values(doc) -> int:
    """The values of a document as the loader counts them (keys included)."""
    if isinstance(doc, dict):
        return 1 + sum(1 + _values(v) for v in doc.values())
    if isinstance(doc, list):
        return 1 + sum(_values(v) for v in doc)
    return 1


def to_yaml(doc, indent: str = "") -> str:
    """Block-style YAML of a plan document (plain scalars: ids, numbers; lists of scalars in flow style)."""
    out = []
    for k, v in doc.items():
        if isinstance(v, dict):
            out.append(f"{indent}{k}:\n" + (to_yaml(v, indent + "  ") if v else ""))
            if not v:
                out[-1] = f"{indent}{k}: {{}}\n"
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            out.append(f"{indent}{k}:\n" + "".join(f"{indent}- " + to_yaml(item, indent + "  ")[len(indent) + 2:]
                                                 for item in v))
        elif isinstance(v, list):
            out.append(f"{indent}{k}: [{', '.join(map(str, v))}]\n")
        else:
            out.append(f"{indent}{k}: {v}\n")
    return "".join(out)


def _fill(doc: dict, limit: int) -> dict:
    """Pad ``doc`` to exactly ``limit`` values, one more constraint at a time (each before declared
    earlier, so the document stays a valid plan)."""
    have = _values(doc)
    req = doc["requires"] if "requires" in doc else doc["strategies"][-1]["requires"]
    ids = doc["parts"]
    index = {p: i for i, p in enumerate(ids)}
    for key in reversed(list(req)):
        if have >= limit:
            break
        if not isinstance(req[key], list):    # `after: before` to `after: [before]`: one value more
            req[key] = [req[key]]
            have += 1
        before = set(req[key])
        for b in range(index[key] - 1, -1, -1):
            if have >= limit:
                break
            if ids[b] not in before:
                req[key].append(ids[b])
                have += 1
    assert _values(doc) == limit, (_values(doc), limit)
    return doc


def strategies_at_value_bound(make=None) -> dict:
    """A plan of the most strategies over the most parts at the value bound (the corner that took
    6.65 s of CPU to check before each strategy's order was built on the parts it constrains only):
    ``make(s)`` gives strategy ``s``'s constraints, by default random ones over all 10,000 parts."""
    loader, _, _, _, plan = _limits()
    P, V, S = plan.MAX_PARTS, loader.MAX_VALUES, plan.MAX_STRATEGIES
    ids = [f"p{i}" for i in range(P)]
    per = (V - (1 + 2 + 2 + P + 2)) // S - 5   # each strategy: its mapping, name, requires key and mapping
    if make is None:
        def make(s):
            return _dag_requires(ids, per, random.Random(s), window=P)
    doc = {"name": "strategies", "parts": ids, "strategies": [{"name": f"s{s}", "requires": make(s)} for s in range(S)]}
    return _fill(doc, V) if _values(doc) < V else doc


def corners():
    """``{name: (bytes, expected)}``: expected is "valid" or the words the refusal must hold."""
    loader, graphs, graphfiles, validate, plan = _limits()
    rng = random.Random(22)
    P, V = plan.MAX_PARTS, loader.MAX_VALUES
    ids = [f"p{i}" for i in range(P)]
    out: dict[str, tuple[bytes, str]] = {}

    def both(name, doc, expected):
        out[name + ".json"] = (json.dumps(doc, indent=1).encode(), expected)
        out[name + ".yaml"] = (to_yaml(doc).encode(), expected)

    # one strategy at the value bound: 10,000 parts and about 110,000 constraints; and one value more
    head = 1 + 2 + 2 + P + 2      # the document, `name`, `parts` and its list, `requires` and its mapping
    one = _fill({"name": "values", "parts": ids, "requires": _dag_requires(ids, V - head, rng)}, V)
    both("values-at-bound", one, "valid")
    over = json.loads(json.dumps(one))
    k = next(iter(over["requires"]))
    over["requires"][k].append(next(p for p in ids if p not in over["requires"][k] and ids.index(p) < ids.index(k)))
    both("values-past-bound", over, f"more than {V:,} values")

    # most strategies over most parts, at the value bound: random constraints, chains, equal, nested, cyclic
    S = plan.MAX_STRATEGIES
    per = (V - (1 + 2 + 2 + P + 2)) // S - 5   # each strategy: its mapping, name, requires key and mapping

    def strategies_doc(name, make):
        return {**strategies_at_value_bound(make), "name": name}

    both("s64-random", {**strategies_at_value_bound(), "name": "s64-random"}, "valid")

    def chain(s):  # a chain over ~per/2 random parts: `after: before`, two values a link
        members = sorted(random.Random(s).sample(range(P), per // 2 + 1))
        return {ids[b]: ids[a] for a, b in zip(members, members[1:])}

    both("s64-chains", strategies_doc("s64-chains", chain), "valid")
    base = {ids[b]: ids[a] for a, b in zip(range(0, P, 1), range(1, per // 2 + 1))}
    both("s64-equal", strategies_doc("s64-equal", lambda s: dict(base)), "admit exactly the same sequences")

    def near(s):  # the base chain without its link s: strategy 0 ... each other one holds the base
        d = dict(base)
        if s:
            d.pop(ids[s * (len(base) // S)], None)
        return d

    both("s64-nested", strategies_doc("s64-nested", near), "valid")

    def cyclic(s):  # the chain closed into a cycle (its last link dropped to stay within the values)
        d = chain(s)
        d.popitem()
        first, last = next(iter(d.values())), next(reversed(d))
        d[first] = last
        return d

    both("s64-cycles", strategies_doc("s64-cycles", cyclic), "has a cycle")
    # unknown ids everywhere (a suggestion is searched for the first hundred only)
    unknown = {"name": "unknown", "parts": ids[:100],
               "requires": {f"u{i}": [f"v{i}", f"w{i}"] for i in range((V - 110) // 4)}}
    both("unknown-ids", unknown, "unknown part")
    # one duplicated part id repeated 10,000 times
    both("duplicate-ids", {"name": "dup", "parts": ["p0"] * P}, "duplicate part id")
    # the schema validator's slow path: the document at the bound with one field the fast check refuses
    slow = json.loads(json.dumps(one))
    slow["parts"][-1] = {"id": slow["parts"][-1], "quantity": 2.5}
    slow["requires"].popitem()
    both("schema-explained", slow, "quantity")
    # deepest nesting accepted by the parser (the schema refuses it) and one level more
    depth = loader.MAX_DEPTH
    deep = {"name": "deep", "parts": ["a"], "description": None}
    nest: list = []
    for _ in range(depth - 2):
        nest = [nest]
    deep["description"] = nest
    both("depth-at-bound", deep, "description")
    deep2 = json.loads(json.dumps(deep))
    deep2["description"] = [deep2["description"]]
    both("depth-past-bound", deep2, f"{depth} levels")
    # text: names of the longest string, as many as fit in the byte bound
    T = validate.MAX_TEXT
    n = loader.MAX_FILE_BYTES // (T + 40) - 1
    both("text-at-bound", {"name": "text", "parts": [{"id": f"p{i}", "name": "x" * T} for i in range(n)]}, "valid")
    both("text-past-bound", {"name": "text", "parts": [{"id": "p0", "name": "x" * (T + 1)}]}, f"at most {T:,}")
    # bytes: a small plan padded to the byte bound, and one byte more
    small = b"name: bytes\nparts: [a, b]\nrequires: {b: [a]}\n"
    out["bytes-at-bound.yaml"] = (small + b"#" * (loader.MAX_FILE_BYTES - len(small) - 1) + b"\n", "valid")
    out["bytes-past-bound.yaml"] = (small + b"#" * (loader.MAX_FILE_BYTES - len(small)) + b"\n",
                                    f"larger than {loader.MAX_FILE_BYTES:,} bytes")
    # YAML aliases: the most, adding the most values
    A = loader.MAX_ALIASES
    each = loader.MAX_ALIAS_VALUES // A - 1
    anchored = "[" + ", ".join(f"p{i}" for i in range(each)) + "]"
    text = (f"name: aliases\nparts: [{', '.join(ids[:A + each + 1])}]\nrequires:\n  p{A + each}: &a {anchored}\n"
            + "".join(f"  p{each + i}: *a\n" for i in range(A)))
    out["aliases-at-bound.yaml"] = (text.encode(), "valid")

    # line-based graph files: 10,000 tasks and the most precedence pairs, at the line bound
    L = graphs.MAX_LINES
    T2, PAIRS = plan.MAX_UNITS, graphs.MAX_PAIRS
    arcs = set()
    while len(arcs) < PAIRS:
        b = rng.randrange(1, T2)
        arcs.add((rng.randrange(max(0, b - 60), b) + 1, b + 1))
    arcs = sorted(arcs)
    body = ("<number of tasks>\n" + f"{T2}\n" + "<task times>\n" + "".join(f"{t} {1 + t % 9}\n" for t in range(1, T2 + 1))
            + "<precedence relations>\n" + "".join(f"{a},{b}\n" for a, b in arcs))
    pad = L - body.count("\n") - 1
    out["alb-at-bound.alb"] = ((body + "\n" * pad + "<end>\n").encode(), "valid")
    out["alb-past-bound.alb"] = ((body + "\n" * (pad + 1) + "<end>\n").encode(), f"at most {L:,} lines")
    in2 = f"{T2}\n" + "".join(f"{1 + t % 9}\n" for t in range(T2)) + "".join(f"{a},{b}\n" for a, b in arcs)
    out["in2-at-bound.IN2"] = ((in2 + "-1,-1\n").encode(), "valid")
    out["in2-pairs-past-bound.IN2"] = ((f"{T2}\n" + "".join(f"{1 + t % 9}\n" for t in range(T2))
                                        + "".join(f"{a},{b}\n" for a, b in arcs) + "1,2\n-1,-1\n").encode(),
                                       f"more than {PAIRS:,} precedence")
    # DOT: the most nodes (with attributes) and edges
    dot = ("digraph big {\n" + "".join(f'  t{t} [label="task {t}", install={1 + t % 9}];\n' for t in range(1, T2 + 1))
           + "".join(f"  t{a} -> t{b};\n" for a, b in arcs) + "}\n")
    out["dot-at-bound.dot"] = (dot.encode(), "valid")
    out["dot-past-bound.dot"] = (dot.replace("}\n", "  t1 -> t3;\n}\n").encode(), f"more than {PAIRS:,} edges")
    # GraphML: the most strategies, each over every part, and the most edges
    G = plan.MAX_STRATEGIES
    nodes = "".join(f'<node id="t{t}"/>' for t in range(1, T2 + 1))
    per_graph = PAIRS // G
    gml = ['<?xml version="1.0"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n']
    for g in range(G):
        chosen = arcs[g * per_graph:(g + 1) * per_graph]
        gml.append(f'<graph id="s{g}" edgedefault="directed">\n{nodes}\n'
                   + "".join(f'<edge source="t{a}" target="t{b}"/>\n' for a, b in chosen) + "</graph>\n")
    gml.append("</graphml>\n")
    out["graphml-at-bound.graphml"] = ("".join(gml).encode(), "valid")
    # GraphML at the element bound: the same, and as many <data> in the nodes as the bound leaves room for
    E = graphfiles.MAX_ELEMENTS
    room = E - (2 + G + G * T2 + per_graph * G)   # graphml, key, graphs, nodes, edges
    gml = ['<?xml version="1.0"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n'
           '<key id="d" for="node" attr.name="install" attr.type="double"/>\n']
    for g in range(G):
        chosen = arcs[g * per_graph:(g + 1) * per_graph]
        with_data = min(room, T2)
        room -= with_data
        gml.append(f'<graph id="s{g}" edgedefault="directed">\n'
                   + "".join(f'<node id="t{t}"><data key="d">{1 + t % 9}</data></node>' if t <= with_data
                             else f'<node id="t{t}"/>' for t in range(1, T2 + 1)) + "\n"
                   + "".join(f'<edge source="t{a}" target="t{b}"/>\n' for a, b in chosen) + "</graph>\n")
    gml.append("</graphml>\n")
    out["graphml-elements-at-bound.graphml"] = ("".join(gml).encode(), "valid")
    # DOT at the token bound: the largest graph, and ignored `x = y;` statements up to the bound
    have = sum(1 for _ in graphfiles._tokens(dot)) - 1
    pad = graphfiles.MAX_TOKENS - have
    dot_full = dot.replace("}\n", "  x = y;\n" * (pad // 4) + "  x;\n" * (pad % 4 // 2) + "}\n")
    assert sum(1 for _ in graphfiles._tokens(dot_full)) - 1 <= graphfiles.MAX_TOKENS
    out["dot-tokens-at-bound.dot"] = (dot_full.encode(), "valid")
    return out


_CHILD = """
import atexit, resource, sys
resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))   # a runaway corner fails instead of swapping

def peak():  # the child's own high-water mark (ru_maxrss would count the parent's pages before exec)
    with open("/proc/self/status") as f:
        hwm = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
    sys.stderr.write(f"\\nVmHWM {hwm}\\n")

atexit.register(peak)
from opportune.cli import main
sys.argv = ["opportune", *sys.argv[1:]]
main()
"""


def run(args: list[str]) -> tuple[float, int, float, int, str]:
    """Run ``opportune ARGS`` in a child: (CPU s, peak RSS bytes, wall s, exit status, standard output)."""
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([sys.executable, "-c", _CHILD, *args], stdout=subprocess.PIPE,
                                stderr=err, env=dict(os.environ, PYTHONHASHSEED="0"))
        out = proc.stdout.read()
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        proc.stdout.close()
        err.seek(0)
        tail = err.read().decode("utf-8", "replace").rsplit("VmHWM ", 1)
    rss = int(tail[1].split()[0]) * 1024 if len(tail) == 2 else usage.ru_maxrss * 1024
    return (usage.ru_utime + usage.ru_stime, rss, time.perf_counter() - start, proc.returncode,
            out.decode("utf-8", "replace"))


def answer(out: str) -> str:
    """`check --json`'s verdict in a few words: valid, or the first error."""
    try:
        doc = json.loads(out)
    except ValueError:
        return "no JSON: " + out[:80]
    if doc.get("valid"):
        return "valid"
    problems = doc.get("problems") or (doc.get("error") or {}).get("problems") or []
    errors = [p for p in problems if p.get("severity") == "error"] or problems
    return errors[0]["message"] if errors else json.dumps(doc)[:120]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="", help="corners whose name contains this")
    parser.add_argument("--count", action="store_true", help="also `count --time-limit 5` on the accepted plans")
    args = parser.parse_args()
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        made = time.process_time()
        cases = {k: v for k, v in corners().items() if args.only in k}
        print(f"{len(cases)} corners written in {time.process_time() - made:.1f} s CPU; shared machine: CPU time "
              f"is what counts\n")
        print(f"{'corner':30} {'MB file':>8} {'CPU s':>6} {'peak MB':>8}  answer")
        for name, (raw, expected) in cases.items():
            path = Path(tmp) / name
            path.write_bytes(raw)
            cpu, rss, wall, code, out = run(["check", str(path), "--json"])
            said = answer(out)
            ok = cpu <= CPU_BOUND and rss <= RSS_BOUND and (said == "valid" if expected == "valid" else expected in said)
            bad += not ok
            print(f"{name:30} {len(raw) / 2**20:8.1f} {cpu:6.2f} {rss / 2**20:8.0f}  "
                  f"{'' if ok else 'FAIL '}{said[:90]}", flush=True)
            if args.count and expected == "valid":
                cpu, rss, wall, code, out = run(["count", str(path), "--time-limit", "5", "--json"])
                try:
                    doc = json.loads(out)
                    said = f"log10 {doc.get('log10')} exact={doc.get('exact')}"
                except ValueError:
                    said = out[:60]
                print(f"{'  count --time-limit 5':30} {'':8} {cpu:6.2f} {rss / 2**20:8.0f}  wall {wall:.2f} s; {said}",
                      flush=True)
            path.unlink()
    print(f"\n{'all corners within' if not bad else f'{bad} corner(s) past'} {CPU_BOUND:g} s CPU and "
          f"{RSS_BOUND >> 20} MB")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
