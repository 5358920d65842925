"""Checking a parsed plan document: schema, ids, cycles, duplicates, redundancy.

:func:`check_document` collects *every* problem rather than stopping at the
first, so that one run of ``opportune check`` tells the user all there is to
fix.  It never enumerates sequences: everything here is polynomial in the
number of parts and constraints.
"""

from __future__ import annotations

import difflib
import json
from functools import lru_cache
from importlib import resources
from typing import TYPE_CHECKING, Any

from opportune.formats.loader import CheckResult, Document
from opportune.formats.problems import Problem
from opportune.plan import Part, Plan, Strategy

if TYPE_CHECKING:
    import jsonschema

DEFAULT_STRATEGY = "default"


@lru_cache(maxsize=1)
def plan_schema() -> dict:
    """The published JSON Schema of plan files (``opportune/formats/plan.schema.json``)."""
    return json.loads(resources.files("opportune.formats").joinpath("plan.schema.json").read_text("utf-8"))


def check_document(doc: Document) -> CheckResult:
    """Check a parsed document against the schema and the rules of a plan.

    Returns the plan (``None`` if there is any error) and all problems,
    errors and warnings, in file order where lines are known.
    """
    problems: list[Problem] = []
    data = doc.data
    if not isinstance(data, dict):
        kind = type(data).__name__ if data is not None else "nothing"
        problems.append(
            Problem(f"a plan must be a mapping with `parts` (and `requires` or `strategies`), found {kind}",
                    "start the file with `parts: [...]`", file=doc.file, line=1, code="type")
        )
        return CheckResult(None, problems)
    data = _normalize_keys(data)
    problems += _schema_problems(data, doc)
    if problems:
        return CheckResult(None, _sorted(problems))

    parts, part_problems = _read_parts(data, doc)
    problems += part_problems
    ids = [p.id for p in parts]
    known = set(ids)
    strategies, strat_problems = _read_strategies(data, doc, known)
    problems += strat_problems
    # Entries with unknown ids were left out above, so cycles can still be found and reported.
    problems += _order_problems(ids, strategies, doc)
    errors = [p for p in problems if p.severity == "error"]
    plan = None
    if not errors:
        name = data.get("name") or (_stem(doc.file) if doc.file else "plan")
        plan = Plan(name=str(name), parts=tuple(parts), strategies=tuple(strategies),
                    source=doc.file, description=data.get("description") or data.get("source"),
                    simulation=data.get("simulation") or {})
    return CheckResult(plan, _sorted(problems))


# ---------------------------------------------------------------- schema


def _normalize_keys(data: dict) -> dict:
    """Integer part ids used as mapping keys become strings (YAML reads `12:` as an int)."""
    data = dict(data)

    def fix(req):
        return {str(k) if isinstance(k, int) and not isinstance(k, bool) else k: v for k, v in req.items()} if isinstance(req, dict) else req

    if "requires" in data:
        data["requires"] = fix(data["requires"])
    if isinstance(data.get("strategies"), list):
        data["strategies"] = [
            {**s, "requires": fix(s.get("requires"))} if isinstance(s, dict) and "requires" in s else s
            for s in data["strategies"]
        ]
    return data


FIELD_HINTS = {
    "quantity": "a whole number of identical units, at least 1",
    "acquire": "a cost or duration, a number ≥ 0",
    "install": "a cost or duration, a number ≥ 0",
    "visibility": "a relative chance of being seen, a number > 0",
    "name": "a string",
    "id": "a part id: a string without spaces or commas",
}


def _schema_problems(data: dict, doc: Document) -> list[Problem]:
    import jsonschema  # here, not at the top: `opportune schema` and `--help` never need it

    validator = jsonschema.Draft202012Validator(plan_schema())
    out = []
    for error in validator.iter_errors(data):
        out += _explain(error, doc)
    # One problem per place and message.
    seen, unique = set(), []
    for p in out:
        key = (p.line, p.message)
        if key not in seen:
            seen.add(key)
            unique.append(p)
    return unique


def _path_text(path: tuple) -> str:
    text = ""
    for step in path:
        text += f"[{step}]" if isinstance(step, int) else (f".{step}" if text else str(step))
    return text or "the plan"


def _describe(value: Any) -> str:
    if isinstance(value, bool):
        return f"{value!r} (YAML reads yes/no/on/off/true/false as booleans: quote it)"
    if value is None:
        return "nothing (an empty value)"
    text = json.dumps(value, default=str)
    return text if len(text) < 60 else text[:57] + "..."


def _type_fits(error: jsonschema.ValidationError) -> bool:
    """False if the error says the value has the wrong type for this (sub)schema altogether."""
    if error.relative_path:
        return True
    if error.validator == "type":
        return False
    if error.validator in ("anyOf", "oneOf"):
        branches: dict[int, list] = {}
        for sub in error.context or []:
            branches.setdefault(sub.relative_schema_path[0], []).append(sub)
        return any(all(_type_fits(e) for e in errs) for errs in branches.values())
    return True


def _explain(error: jsonschema.ValidationError, doc: Document) -> list[Problem]:
    path = tuple(error.absolute_path)
    line = doc.line(path)
    where = _path_text(path)
    v = error.validator
    field = next((p for p in reversed(path) if isinstance(p, str)), None)

    def problem(message, hint, code="schema", parts=()):
        return Problem(message, hint, file=doc.file, line=line, parts=tuple(parts), code=code)

    if v in ("oneOf", "anyOf"):
        # Pick the branch whose type matches the value and explain its errors instead.
        branches: dict[int, list] = {}
        for sub in error.context or []:
            branches.setdefault(sub.relative_schema_path[0], []).append(sub)
        # The branch whose type fits the value holds the real problems.
        matching = [errs for errs in branches.values() if errs and all(_type_fits(e) for e in errs)]
        if len(matching) == 1:
            out = []
            for sub in matching[0]:
                out += _explain(sub, doc)
            if out:
                return out
        if "parts" in path and len(path) == 2:
            return [problem(f"{where}: {_describe(error.instance)} is not a part",
                            "write a part id (no spaces or commas) or a mapping {id, name, quantity, acquire, install}", "type")]
        if "requires" in path:
            return [problem(f"{where}: {_describe(error.instance)} is not a part id or a list of part ids",
                            "write `part: [before1, before2]` with part ids (no spaces or commas)", "type")]
        return [problem(f"{where}: {_describe(error.instance)} is not allowed here", "see the plan schema", "type")]
    if v == "required":
        missing = error.message.split("'")[1] if "'" in error.message else error.message
        if missing == "parts":
            return [problem("the plan has no `parts`", "list the parts: `parts: [a, b, c]`", "missing")]
        return [problem(f"{where}: `{missing}` is missing", f"add `{missing}:`", "missing")]
    if v == "additionalProperties":
        allowed = sorted(error.schema.get("properties", {}))
        extras = [k for k in error.instance if k not in error.schema.get("properties", {})]
        out = []
        for extra in extras:
            guess = difflib.get_close_matches(str(extra), allowed, n=1)
            hint = f"did you mean `{guess[0]}`?" if guess else f"allowed fields: {', '.join(allowed)}"
            line_k = doc.line(path + (extra,))
            out.append(Problem(f"{where}: unknown field `{extra}`", hint, file=doc.file, line=line_k, code="unknown-field"))
        return out
    if v == "not" and not path:
        return [problem("the plan has both `requires` and `strategies`",
                        "use `requires` for a single strategy, or put every strategy under `strategies`", "conflict")]
    if v == "type":
        expected = error.validator_value
        expected = " or ".join(expected) if isinstance(expected, list) else expected
        return [problem(f"{where}: expected {expected}, got {_describe(error.instance)}",
                        FIELD_HINTS.get(field, f"write a {expected}") if field else f"write a {expected}", "type")]
    if v == "minimum":
        if field == "quantity":
            return [problem(f"{where}: quantity must be at least 1, got {error.instance}",
                            "give the number of identical units (1 or more), or remove the part", "quantity")]
        return [problem(f"{where}: {field} must be ≥ 0, got {error.instance}",
                        "costs and durations cannot be negative", "negative-cost")]
    if v == "minItems":
        if path == ("parts",):
            return [problem("the plan has no parts", "list at least one part under `parts`", "empty")]
        return [problem(f"{where}: must not be empty", "add at least one entry or remove the field", "empty")]
    if v == "minLength":
        return [problem(f"{where}: must not be empty", "write a non-empty string", "empty")]
    if v == "pattern":
        return [problem(f"{where}: {_describe(error.instance)} is not a valid part id",
                        "part ids may not contain spaces, commas or '#'; use the `name` field for a readable name", "part-id")]
    return [problem(f"{where}: {error.message}", "see the plan schema (opportune schema)")]


# ---------------------------------------------------------------- parts and strategies


def _read_parts(data: dict, doc: Document) -> tuple[list[Part], list[Problem]]:
    parts, problems, first_line = [], [], {}
    for i, item in enumerate(data["parts"]):
        line = doc.line(("parts", i))
        if isinstance(item, dict):
            pid = str(item["id"])
            part = Part(id=pid, name=item.get("name"), quantity=int(item.get("quantity", 1)),
                        acquire=float(item.get("acquire", 1.0)), install=float(item.get("install", 1.0)),
                        visibility=float(item.get("visibility", 1.0)))
        else:
            pid = str(item)
            part = Part(id=pid)
        if pid in first_line:
            problems.append(Problem(f"duplicate part id '{pid}' (first declared at line {first_line[pid]})"
                                    if first_line[pid] else f"duplicate part id '{pid}'",
                                    "give every part a unique id; for identical units use `quantity`",
                                    file=doc.file, line=line, parts=(pid,), code="duplicate-part"))
            continue
        first_line[pid] = line
        parts.append(part)
    return parts, problems


def _read_strategies(data: dict, doc: Document, known: set[str]) -> tuple[list[Strategy], list[Problem]]:
    if "strategies" in data:
        entries = [(("strategies", i), s.get("name") or f"strategy {i + 1}", s.get("requires"))
                   for i, s in enumerate(data["strategies"])]
    else:
        entries = [((), DEFAULT_STRATEGY, data.get("requires"))]
    strategies, problems, names = [], [], {}
    for path, name, requires in entries:
        if name in names:
            problems.append(Problem(f"two strategies are named '{name}'", "give each strategy its own name",
                                    file=doc.file, line=doc.line(path + ("name",)), code="duplicate-strategy"))
        names[name] = path
        req: dict[str, tuple[str, ...]] = {}
        for key, before in (requires or {}).items():
            kpath = path + ("requires", key)
            key = str(key)
            line = doc.line(kpath)
            if before is None:
                before = []
            elif not isinstance(before, list):
                before = [before]
            before = [str(b) for b in before]
            ok = True
            for pid in [key] + before:
                if pid not in known:
                    ok = False
                    guess = difflib.get_close_matches(pid, sorted(known), n=1)
                    role = "listed with requirements" if pid == key else f"in the requirements of '{key}'"
                    problems.append(Problem(
                        f"unknown part '{pid}' {role} (strategy '{name}')",
                        (f"did you mean '{guess[0]}'? " if guess else "") + "declare it under `parts` or fix the id",
                        file=doc.file, line=line, parts=(pid,), code="unknown-part"))
            if key in before:
                ok = False
                problems.append(Problem(f"part '{key}' requires itself (strategy '{name}')",
                                        f"remove '{key}' from its own list", file=doc.file, line=line,
                                        parts=(key,), code="self-requirement"))
            dups = sorted({b for b in before if before.count(b) > 1})
            for d in dups:
                problems.append(Problem(f"'{key}' lists '{d}' more than once (strategy '{name}')",
                                        "list each required part once", file=doc.file, line=line,
                                        parts=(key, d), severity="warning", code="repeated"))
            if ok:
                req[key] = tuple(dict.fromkeys(before))
        strategies.append(Strategy(name=str(name), requires=req))
    return strategies, problems


def _order_problems(ids: list[str], strategies: list[Strategy], doc: Document) -> list[Problem]:
    """Cycles, duplicate or subsumed strategies, redundant constraints."""
    from opportune.engine.poset import Poset

    index = {pid: i for i, pid in enumerate(ids)}
    problems: list[Problem] = []
    posets: list[Poset | None] = []
    spath = ("strategies",) if len(strategies) > 1 or "strategies" in (doc.data or {}) else ()
    for si, s in enumerate(strategies):
        base = spath + (si,) if spath else ()
        cycles = find_cycles(ids, s.requires)
        for cycle in cycles:
            arrow = " -> ".join(cycle)
            problems.append(Problem(
                f"strategy '{s.name}' has a cycle: {arrow}; an over-constrained plan has no admissible sequence",
                f"remove one of these constraints (each '{cycle[0]} -> {cycle[1]}' means '{cycle[0]}' must come before '{cycle[1]}')",
                file=doc.file, line=doc.line(base + ("requires", cycle[1])), parts=tuple(cycle[:-1]), code="cycle"))
        if cycles:
            posets.append(None)
            continue
        pairs = [(index[b], index[a]) for b, a in s.pairs()]
        poset = Poset.from_pairs(len(ids), pairs)
        posets.append(poset)
        cover = set(poset.cover_pairs())
        for b, a in pairs:
            if (b, a) not in cover:
                via = _path_between(poset, b, a, ids)
                problems.append(Problem(
                    f"'{ids[a]}' requires '{ids[b]}', which is already implied by {' -> '.join(via)} (strategy '{s.name}')",
                    "the constraint is redundant: remove it, or keep it as documentation",
                    file=doc.file, line=doc.line(base + ("requires", ids[a])), parts=(ids[b], ids[a]),
                    severity="warning", code="redundant"))
    for i in range(len(strategies)):
        for j in range(i):
            pi, pj = posets[i], posets[j]
            if pi is None or pj is None:
                continue
            line = doc.line(spath + (i,)) if spath else None
            if pi == pj:
                problems.append(Problem(
                    f"strategies '{strategies[j].name}' and '{strategies[i].name}' admit exactly the same sequences",
                    f"remove '{strategies[i].name}', it adds nothing", file=doc.file, line=line, code="duplicate-strategy"))
            elif _contains(pi, pj) or _contains(pj, pi):
                small, big = (i, j) if _contains(pi, pj) else (j, i)
                problems.append(Problem(
                    f"every sequence of strategy '{strategies[small].name}' is also admitted by '{strategies[big].name}'",
                    f"'{strategies[small].name}' adds no sequences; remove it unless you keep it on purpose",
                    file=doc.file, line=line, severity="warning", code="subsumed-strategy"))
    return problems


def _contains(stricter, looser) -> bool:
    """True if every constraint of ``looser`` is in ``stricter`` (so stricter's sequences ⊆ looser's)."""
    return all((looser.below[k] & ~stricter.below[k]) == 0 for k in range(stricter.n))


def _path_between(poset, b: int, a: int, ids: list[str]) -> list[str]:
    """A chain of covers from b to a that is longer than the direct edge."""
    covers: dict[int, list[int]] = {}
    for x, y in poset.cover_pairs():
        covers.setdefault(x, []).append(y)
    # DFS over covers from b to a.
    stack = [(b, [b])]
    while stack:
        node, path = stack.pop()
        if node == a and len(path) > 2:
            return [ids[k] for k in path]
        for nxt in covers.get(node, []):
            if nxt == a or (poset.below[a] >> nxt) & 1:
                stack.append((nxt, path + [nxt]))
    return [ids[b], ids[a]]


def find_cycles(ids: list[str], requires) -> list[list[str]]:
    """One cycle per strongly connected component of the 'must come before' graph.

    Each cycle is a list of ids that starts and ends with the same id, e.g.
    ``['ba', 'rl', 'ba']`` (ba before rl before ba).  Linear time (Tarjan).
    """
    succ: dict[str, list[str]] = {pid: [] for pid in ids}
    for after, befores in requires.items():
        for before in befores:
            if before in succ and after in succ:
                succ[before].append(after)
    index_of, low, on_stack, stack, sccs = {}, {}, set(), [], []
    counter = 0
    for root in ids:
        if root in index_of:
            continue
        work = [(root, iter(succ[root]))]
        index_of[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, it = work[-1]
            advanced = False
            for nxt in it:
                if nxt not in index_of:
                    index_of[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(succ[nxt])))
                    advanced = True
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index_of[nxt])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index_of[node]:
                comp = []
                while True:
                    x = stack.pop()
                    on_stack.discard(x)
                    comp.append(x)
                    if x == node:
                        break
                if len(comp) > 1:
                    sccs.append(set(comp))
    cycles = []
    order = {pid: i for i, pid in enumerate(ids)}
    for comp in sccs:
        start = min(comp, key=order.__getitem__)
        # BFS inside the component back to start: the shortest cycle through it.
        prev, frontier, found = {start: None}, [start], None
        while frontier and found is None:
            nxt_frontier = []
            for node in frontier:
                for nxt in succ[node]:
                    if nxt not in comp:
                        continue
                    if nxt == start:
                        found = node
                        break
                    if nxt not in prev:
                        prev[nxt] = node
                        nxt_frontier.append(nxt)
                if found is not None:
                    break
            frontier = nxt_frontier
        path = [found]
        while prev[path[-1]] is not None:
            path.append(prev[path[-1]])
        path.reverse()
        cycles.append(path + [start])
    return cycles


def _sorted(problems: list[Problem]) -> list[Problem]:
    return sorted(problems, key=lambda p: (p.severity != "error", p.line or 0))


def _stem(file: str) -> str:
    from pathlib import Path

    return Path(file).stem
