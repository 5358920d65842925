"""Checking a parsed plan document: schema, ids, cycles, duplicates, redundancy.

:func:`check_document` collects *every* problem rather than stopping at the
first, so that one run of ``opportune check`` tells the user all there is to
fix.  It never enumerates sequences: everything here is polynomial in the
number of parts and constraints.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from functools import lru_cache

from opportune.formats.documents import CheckResult, Document, file_stem
from opportune.formats.problems import CONTROL_CHARS, Problem, closest
from opportune.formats.shapes import COORDINATE, HINT as SHAPE_HINT, shape_problems, too_many_points
from opportune.planning.plan import (MAX_CONSTRAINTS, MAX_DIMENSION, MAX_PARTS, MAX_QUANTITY, MAX_STRATEGIES, MAX_UNITS,
                            MAX_WEIGHT, MIN_DIMENSION, SHAPES, Part, Plan, Strategy)
from opportune.limits import MAX_BODY_POINTS, MAX_ID, MAX_SHAPE_BODIES, MAX_TEXT  # noqa: F401 (their home: the one table of limits)

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

    import jsonschema

DEFAULT_STRATEGY = "default"
# A file can hold a problem on every line: past this many of one kind, one problem sums up the rest.
MAX_PER_KIND = 100
#: Characters no text of a plan may hold: lone UTF-16 surrogates (not Unicode text), C0 controls but tab,
#: line feed and carriage return, DEL and C1 controls (an ESC sequence in a part id would reach the
#: terminal of everyone who checks the plan; U+0000 cannot be stored in PostgreSQL).
_BAD_CHAR = re.compile(f"[\ud800-\udfff{CONTROL_CHARS}]")


def _close(word: str, choices) -> list[str]:
    """The closest of ``choices`` to a misspelt ``word`` (a list of at most one): for a suggestion."""
    guess = closest(word, choices)
    return [] if guess is None else [guess]


@lru_cache(maxsize=1)
def plan_schema() -> dict:
    """The published JSON Schema of plan files (``opportune/formats/plan.schema.json``)."""
    import json
    from importlib import resources     # 9 ms of imports: only for the schema's users

    return json.loads(resources.files("opportune.formats").joinpath("plan.schema.json").read_text("utf-8"))


def check_document(doc: Document, *, allow_cycles: bool = False) -> CheckResult:
    """Check a parsed document against the schema and the rules of a plan.

    Returns the plan (``None`` if there is any error) and all problems,
    errors and warnings, in file order where lines are known.  ``allow_cycles``
    (for :mod:`opportune.derive.relax` only) leaves cyclic strategies in the plan
    instead of refusing it: such a plan has no admissible sequence.
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
    # Text that is not Unicode (half of a surrogate pair) or numbers that are not finite cannot be
    # shown, stored or computed with: refused first, each with its place.
    problems += _value_problems(data, doc)
    if problems:
        return CheckResult(None, _capped(_sorted(problems)))
    data = _normalize_keys(data)
    # Sizes first: the schema validator's time grows with them.
    problems += _size_problems(data, doc)
    if problems:
        return CheckResult(None, _capped(_sorted(problems)))
    problems += _schema_problems(data, doc)
    if problems:
        return CheckResult(None, _capped(_sorted(problems)))

    problems += [Problem(message, SHAPE_HINT, file=doc.file, line=doc.line(("parts", i, "geometry")),
                         parts=(str(data["parts"][i]["id"]),), code="geometry")
                 for i, message in shape_problems(data["parts"])]
    parts, part_problems = _read_parts(data, doc)
    problems += part_problems
    units = sum(p.quantity for p in parts)
    if units > MAX_UNITS:
        problems.append(Problem(
            f"the plan has {units:,} units in all (the sum of the quantities); at most {MAX_UNITS:,} are accepted",
            "split the plan, or lower the quantities (the engine's memory grows with the square of the units)",
            file=doc.file, line=doc.line(("parts",)), code="limit"))
        return CheckResult(None, _capped(_sorted(problems)))
    ids = [p.id for p in parts]
    known = set(ids)
    andor = None
    unlisted_unknown = [0]
    ways = None
    if "ways" in data:      # each part's ways in: no strategies (opportune.formats.ways)
        from opportune.formats.ways import check_ways

        ways, ways_problems = check_ways(data, doc, parts)
        return _ways_result(data, doc, parts, ways, problems + ways_problems)
    if "assemblies" in data:  # an AND/OR graph (issue 15): expanded into strategies, checked there
        from opportune.formats.andor import check_assemblies

        strategies, andor, strat_problems = check_assemblies(data, doc, ids)
    else:
        strategies, strat_problems = _read_strategies(data, doc, known, unlisted_unknown)
    problems += strat_problems
    # Entries with unknown ids were left out above, so cycles can still be found and reported.
    order_problems, unlisted, orders = _order_problems(ids, strategies, doc, allow_cycles=allow_cycles)
    problems += order_problems
    errors = [p for p in problems if p.severity == "error"]
    plan = None
    if not errors:
        name = data.get("name") or (file_stem(doc.file) if doc.file else "plan")
        plan = Plan(name=str(name), parts=tuple(parts), strategies=tuple(strategies),
                    source=doc.file, description=data.get("description") or data.get("source"),
                    simulation=data.get("simulation") or {}, andor=andor)
        if all(o is not None for o in orders):  # built once: the summary (`check`) uses them again
            from opportune.planning.orders import keep_summary

            object.__setattr__(plan, "_strategy_summaries", tuple(keep_summary(o) for o in orders))
    unlisted[("unknown-part", "error")] += unlisted_unknown[0]
    return CheckResult(plan, _capped(_sorted(problems), unlisted))


def _ways_result(data: dict, doc: Document, parts: list[Part], ways: dict, problems: list[Problem]) -> CheckResult:
    """The check's result for a plan written as ways: the plan if no error, searched for a sequence."""
    plan = None
    if not any(p.severity == "error" for p in problems):
        from opportune.formats.ways import feasibility_problems, ways_plan

        name = data.get("name") or (file_stem(doc.file) if doc.file else "plan")
        plan = ways_plan(str(name), parts, ways, description=data.get("description") or data.get("source"),
                         simulation=data.get("simulation") or {}, source=doc.file)
        problems = problems + feasibility_problems(plan, doc)
        if any(p.severity == "error" for p in problems):
            plan = None
    return CheckResult(plan, _capped(_sorted(problems)))


def _size_problems(data: dict, doc: Document) -> list[Problem]:
    """Parts, strategies and declared constraints over the stated limits (:mod:`opportune.planning.plan`)."""
    out = []
    parts, strategies = data.get("parts"), data.get("strategies")
    if isinstance(parts, list) and len(parts) > MAX_PARTS:
        out.append(Problem(f"parts: {len(parts):,} parts; at most {MAX_PARTS:,} are accepted",
                           "split the plan into smaller ones", file=doc.file, line=doc.line(("parts",)), code="limit"))
    if isinstance(strategies, list) and len(strategies) > MAX_STRATEGIES:
        out.append(Problem(f"strategies: {len(strategies):,} strategies; at most {MAX_STRATEGIES:,} are accepted",
                           "keep the strategies that add sequences (check warns of those that do not)",
                           file=doc.file, line=doc.line(("strategies",)), code="limit"))
        return out
    for i, item in enumerate(parts if isinstance(parts, list) else ()):
        pid = item.get("id") if isinstance(item, dict) else item
        if isinstance(pid, str) and len(pid) > MAX_ID:    # a look names parts by id: ids are short
            out.append(Problem(f"parts[{i}]: a part id of {len(pid):,} characters; at most {MAX_ID:,} are accepted",
                               "shorten the id, and put a longer text under the part's `name`", file=doc.file,
                               line=doc.line(("parts", i)), parts=(pid[:40] + "…",), code="limit"))
    many = too_many_points(parts)
    if many:
        out.append(Problem(many, SHAPE_HINT, file=doc.file, line=doc.line(("parts",)), code="limit"))
    declared = 0
    for req in [data.get("requires")] + [s.get("requires") for s in (strategies if isinstance(strategies, list) else ())
                                         if isinstance(s, dict)]:
        if isinstance(req, dict):
            declared += sum(len(v) if isinstance(v, list) else 1 for v in req.values())
    if declared > MAX_CONSTRAINTS:
        out.append(Problem(f"the plan declares {declared:,} constraints; at most {MAX_CONSTRAINTS:,} are accepted",
                           "split the plan; list each constraint once", file=doc.file, line=1, code="limit"))
    return out


def _clean_values(data: Any) -> bool:
    """True when no string or key is longer than :data:`MAX_TEXT` or holds a lone surrogate and every
    float is finite: the common case, checked without building the paths :func:`_value_problems`
    reports.  Iterative, O(number of values); lists of strings are searched at once (C speed)."""
    stack = [data]
    while stack:
        value = stack.pop()
        kind = type(value)
        if kind is dict:
            keys = [k for k in value if type(k) is str]
            if keys and (max(map(len, keys)) > MAX_TEXT or _BAD_CHAR.search("".join(keys))):
                return False
            stack.extend(value.values())
        elif kind is list or kind is tuple:
            texts = [v for v in value if type(v) is str]
            if texts and (max(map(len, texts)) > MAX_TEXT or _BAD_CHAR.search("".join(texts))):
                return False
            if len(texts) < len(value):
                stack.extend(v for v in value if type(v) is not str)
        elif kind is str:
            if len(value) > MAX_TEXT or _BAD_CHAR.search(value):
                return False
        elif isinstance(value, float) and not math.isfinite(value):
            return False
        elif isinstance(value, (str, dict, list, tuple)):  # subclasses: the full walk judges them
            return False
    return True


def _value_problems(data: Any, doc: Document) -> list[Problem]:
    """Strings longer than :data:`MAX_TEXT` or with lone surrogates, and numbers that are not finite,
    anywhere in the document.

    An iterative walk, O(number of values); a parsed file's depth is already bounded by the loader.
    """
    if _clean_values(data):
        return []
    out: list[Problem] = []
    stack: list[tuple[Any, tuple]] = [(data, ())]
    while stack:
        value, path = stack.pop()
        if isinstance(value, dict):
            for k, v in value.items():
                if isinstance(k, str) and (len(k) > MAX_TEXT or _BAD_CHAR.search(k)):
                    out.append(_bad_text(k, path, doc))
                    continue
                stack.append((v, path + (k,)))
        elif isinstance(value, (list, tuple)):
            stack.extend((v, path + (i,)) for i, v in enumerate(value))
        elif isinstance(value, str):
            if len(value) > MAX_TEXT or _BAD_CHAR.search(value):
                out.append(_bad_text(value, path, doc))
        elif isinstance(value, float) and not math.isfinite(value):
            out.append(Problem(f"{_path_text(path)}: {value!r} is not a finite number",
                               "write a number (costs and weights are finite numbers ≥ 0)",
                               file=doc.file, line=doc.line(path), code="type"))
    return out


def _bad_text(text: str, path: tuple, doc: Document) -> Problem:
    if len(text) > MAX_TEXT:
        return Problem(f"{_path_text(path)}: a text of {len(text):,} characters; at most {MAX_TEXT:,} are accepted",
                       "shorten it: ids and names are short, a description a few paragraphs",
                       file=doc.file, line=doc.line(path), code="limit")
    char = _BAD_CHAR.search(text).group()
    shown = ascii(text if len(text) <= 40 else text[:37] + "...")
    if "\ud800" <= char <= "\udfff":
        return Problem(f"{_path_text(path)}: {shown} contains {ascii(char)[1:-1]}, half of a UTF-16 surrogate pair: "
                       "it is not valid Unicode text",
                       "write the character itself, or both halves of the pair (e.g. \\ud83d\\ude00)",
                       file=doc.file, line=doc.line(path), code="text")
    return Problem(f"{_path_text(path)}: {shown} contains the control character U+{ord(char):04X}: a plan's "
                   "text is printable (tab and line breaks aside)",
                   "remove it (a terminal would act on it; a database refuses U+0000)",
                   file=doc.file, line=doc.line(path), code="text")


def _capped(problems: list[Problem], unlisted: Counter | None = None) -> list[Problem]:
    """At most :data:`MAX_PER_KIND` problems of each code and severity, then one that counts the rest.

    ``unlisted`` counts, by ``(code, severity)``, problems found but never built (past the cap).
    """
    seen: Counter = Counter()
    kept: list[Problem] = []
    dropped: dict[tuple[str, str], Problem] = {}
    for p in problems:
        key = (p.code, p.severity)
        seen[key] += 1
        if seen[key] <= MAX_PER_KIND:
            kept.append(p)
        else:
            dropped.setdefault(key, p)
    for (code, severity), first in dropped.items():
        more = seen[(code, severity)] - MAX_PER_KIND + (unlisted or {}).get((code, severity), 0)
        kept.append(Problem(f"and {more:,} more problems like the ones above ({code}), the first of them here",
                            "fix the ones listed and check again", file=first.file, line=first.line,
                            severity=severity, code=code))
    return kept


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
    "quantity": "a whole number of identical units, from 1 to 10,000",
    "acquire": "a cost or duration, a number ≥ 0",
    "install": "a cost or duration, a number ≥ 0",
    "visibility": "a relative chance of being seen, a number > 0",
    "name": "a string",
    "id": "a part id: a string without spaces or commas",
    "part": "a part id: a string without spaces or commas",
    "weight": "the price of dropping the constraint (opportune relax): a number > 0 and at most 1,000,000",
}


_PART_ID = re.compile(r"^[^\s,#]+$")
_PLAN_KEYS = frozenset({"name", "description", "source", "parts", "requires", "strategies"})
_PART_KEYS = frozenset({"id", "name", "quantity", "acquire", "install", "visibility", "geometry"})
GEOMETRY_HINT = (f"write `geometry: {{box: [x, y, z]}}` (edge lengths) or `geometry: {{cylinder: [radius, height]}}`, "
                 f"in metres, each from {MIN_DIMENSION:g} to {MAX_DIMENSION:g}")
_STRATEGY_KEYS = frozenset({"name", "description", "requires"})


def _is_part_id(v) -> bool:
    if isinstance(v, str):
        return _PART_ID.fullmatch(v) is not None
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _is_cost(v, *, positive: bool = False) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and (v > 0 if positive else v >= 0)


def _is_geometry(geometry) -> bool:
    """True only if ``geometry`` is one shape of :data:`~opportune.planning.plan.SHAPES` with its dimensions in bounds."""
    if not (isinstance(geometry, dict) and len(geometry) == 1):
        return False
    (shape, dims), = geometry.items()
    if shape == "convex":
        return _is_convex(dims)
    return (shape in SHAPES and isinstance(dims, list) and len(dims) == SHAPES[shape]
            and all(_is_cost(d) and MIN_DIMENSION <= d <= MAX_DIMENSION for d in dims))


def _is_convex(bodies) -> bool:
    """True only if ``bodies`` certainly fits the schema's ``convex`` shape (the bounds of :mod:`opportune.formats.shapes`)."""
    def is_point(p) -> bool:
        return (isinstance(p, list) and len(p) == 3 and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                                            and -COORDINATE <= c <= COORDINATE for c in p))

    return (isinstance(bodies, list) and 1 <= len(bodies) <= MAX_SHAPE_BODIES
            and all(isinstance(b, list) and 4 <= len(b) <= MAX_BODY_POINTS and all(is_point(p) for p in b)
                    for b in bodies))


def _is_requires(req) -> bool:
    if req is None:
        return True
    if not isinstance(req, dict):
        return False
    for before in req.values():
        if isinstance(before, list):
            if not all(_is_part_id(b) for b in before):
                return False
        elif before is not None and not _is_part_id(before):
            return False
    return True


def _fits_schema(data: dict) -> bool:
    """True only if ``data`` certainly satisfies the plan schema: a plain, linear-time walk.

    It accepts a subset of what the schema accepts (anything unusual, e.g. a ``simulation`` section
    or a quantity written ``2.0``, answers False), so that the schema validator, far slower a value
    (docs/bounds.md), runs only on documents that may have problems, and explains them.
    """
    if not _PLAN_KEYS.issuperset(data) or "parts" not in data or ("requires" in data and "strategies" in data):
        return False
    for k in ("name", "description", "source"):
        if k in data and not (isinstance(data[k], str) and (data[k] or k != "name")):
            return False
    parts = data["parts"]
    if not isinstance(parts, list) or not 1 <= len(parts) <= MAX_PARTS:
        return False
    for item in parts:
        if isinstance(item, dict):
            if not _PART_KEYS.issuperset(item) or not _is_part_id(item.get("id")):
                return False
            if "name" in item and not isinstance(item["name"], str):
                return False
            q = item.get("quantity", 1)
            if not (isinstance(q, int) and not isinstance(q, bool) and 1 <= q <= MAX_QUANTITY):
                return False
            if not all(_is_cost(item[k]) for k in ("acquire", "install") if k in item):
                return False
            if "visibility" in item and not _is_cost(item["visibility"], positive=True):
                return False
            if "geometry" in item and not _is_geometry(item["geometry"]):
                return False
        elif not _is_part_id(item):
            return False
    if "requires" in data and not _is_requires(data["requires"]):
        return False
    if "strategies" in data:
        strategies = data["strategies"]
        if not isinstance(strategies, list) or not 1 <= len(strategies) <= MAX_STRATEGIES:
            return False
        for st in strategies:
            if not isinstance(st, dict) or not _STRATEGY_KEYS.issuperset(st) or "requires" not in st:
                return False
            if "name" in st and not (isinstance(st["name"], str) and st["name"]):
                return False
            if "description" in st and not isinstance(st["description"], str):
                return False
            if not _is_requires(st["requires"]):
                return False
    return True


def _is_part(item) -> bool:
    """True only if ``item`` certainly satisfies the schema's ``parts`` items (an id or a part mapping)."""
    if not isinstance(item, dict):
        return _is_part_id(item)
    q = item.get("quantity", 1)
    return (_PART_KEYS.issuperset(item) and _is_part_id(item.get("id"))
            and ("name" not in item or isinstance(item["name"], str))
            and isinstance(q, int) and not isinstance(q, bool) and 1 <= q <= MAX_QUANTITY
            and all(_is_cost(item[k]) for k in ("acquire", "install") if k in item)
            and ("visibility" not in item or _is_cost(item["visibility"], positive=True))
            and ("geometry" not in item or _is_geometry(item["geometry"])))


def _for_schema(data: dict) -> tuple[dict, dict[tuple, list[int]]]:
    """A copy of ``data`` without the entries the schema certainly accepts, and where the kept items were.

    The schema judges every item of ``parts`` and of a requirement list, and every entry of a
    ``requires`` mapping, on its own (no uniqueness, no size limit on them but the ones checked
    before), so the ones that certainly fit are left out: the validator then costs time only for
    what may be wrong, however long the lists.  Returns the copy and, per shortened list, the
    original index of each item kept (see :func:`_original_path`).
    """
    where: dict[tuple, list[int]] = {}

    def keep(items: list, path: tuple, fits, at_least_one: bool = False) -> list:
        kept = [i for i, v in enumerate(items) if not fits(v)]
        if at_least_one and not kept and items:
            kept = [0]
        if len(kept) < len(items):
            where[path] = kept
            return [items[i] for i in kept]
        return items

    def requires(req, path: tuple):
        if not isinstance(req, dict):
            return req
        out = {}
        for k, v in req.items():
            if v is None or _is_part_id(v):
                continue
            out[k] = keep(v, path + (k,), _is_part_id) if isinstance(v, list) else v
        return out

    data = dict(data)
    if isinstance(data.get("parts"), list):
        data["parts"] = keep(data["parts"], ("parts",), _is_part, at_least_one=True)
    if "requires" in data:
        data["requires"] = requires(data["requires"], ("requires",))
    if isinstance(data.get("strategies"), list):
        data["strategies"] = [{**st, "requires": requires(st["requires"], ("strategies", i, "requires"))}
                              if isinstance(st, dict) and "requires" in st else st
                              for i, st in enumerate(data["strategies"])]
    if isinstance(data.get("assemblies"), dict):  # AND/OR graphs: the assemblies that certainly fit are left out
        from opportune.formats.andor import fits_schema

        fits = [k for k, ways in data["assemblies"].items() if fits_schema(k, ways, _is_part_id)]
        if fits:
            drop = set(fits[1:]) if len(fits) == len(data["assemblies"]) else set(fits)  # the schema wants one
            data["assemblies"] = {k: v for k, v in data["assemblies"].items() if k not in drop}
    return data, where


def _original_path(path: tuple, where: dict[tuple, list[int]]) -> tuple:
    """A path into the copy made by :func:`_for_schema` as a path into the original document."""
    for k in range(len(path)):
        kept = where.get(path[:k])
        if kept is not None and isinstance(path[k], int) and path[k] < len(kept):
            path = path[:k] + (kept[path[k]],) + path[k + 1:]
    return path


def _schema_problems(data: dict, doc: Document) -> list[Problem]:
    if _fits_schema(data):
        return []
    import jsonschema  # here, not at the top: `opportune schema` and `--help` never need it

    validator = jsonschema.Draft202012Validator(plan_schema())
    reduced, where = _for_schema(data)
    out = []
    for error in validator.iter_errors(reduced):
        out += _explain(error, doc, where)
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
    import json

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


def _explain(error: jsonschema.ValidationError, doc: Document, where_kept: dict | None = None) -> list[Problem]:
    path = _original_path(tuple(error.absolute_path), where_kept or {})
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
                out += _explain(sub, doc, where_kept)
            if out:
                return out
        if "parts" in path and len(path) == 2:
            return [problem(f"{where}: {_describe(error.instance)} is not a part",
                            "write a part id (no spaces or commas) or a mapping {id, name, quantity, acquire, install}", "type")]
        if "requires" in path:
            return [problem(f"{where}: {_describe(error.instance)} is not a part id or a list of part ids",
                            "write `part: [before1, before2]` with part ids (no spaces or commas), or "
                            "`{part: before1, weight: 5}` for a weighted constraint", "type")]
        return [problem(f"{where}: {_describe(error.instance)} is not allowed here", "see the plan schema", "type")]
    if "convex" in path:
        shown = _describe(error.instance)
        what = {"minimum": f"{shown} is below -{COORDINATE:g} m", "maximum": f"{shown} is above {COORDINATE:g} m",
                "minItems": f"{shown} has too few entries (a body has 4 corners or more, a corner 3 coordinates)",
                "maxItems": f"{shown} has too many entries (at most {MAX_SHAPE_BODIES} bodies of {MAX_BODY_POINTS} "
                            "corners, a corner 3 coordinates)"}.get(v, f"{shown} is not a convex shape")
        return [problem(f"{where}: {what}", SHAPE_HINT, "geometry")]
    if "geometry" in path:
        shown = _describe(error.instance)
        what = {"minimum": f"{shown} is below {MIN_DIMENSION:g} m", "maximum": f"{shown} is above {MAX_DIMENSION:g} m",
                "additionalProperties": f"{shown} is not a shape (box, cylinder or convex)",
                "maxProperties": f"{shown} gives more than one shape", "minProperties": "no shape is given",
                "minItems": f"{shown} has too few dimensions", "maxItems": f"{shown} has too many dimensions",
                }.get(v, f"{shown} is not a geometry")
        return [problem(f"{where}: {what}", GEOMETRY_HINT, "geometry")]
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
            guess = _close(str(extra), allowed)
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
    if v == "maximum" and field == "quantity":
        return [problem(f"{where}: quantity must be at most {error.validator_value:,}, got {_describe(error.instance)}",
                        f"a plan holds at most {MAX_UNITS:,} units in all: split the plan", "limit")]
    if field == "weight" and v in ("exclusiveMinimum", "maximum"):
        return [problem(f"{where}: a constraint's weight must be > 0 and at most {MAX_WEIGHT:,}, got "
                        f"{_describe(error.instance)}", FIELD_HINTS["weight"], "weight")]
    if v == "maxItems":
        what = "parts" if path == ("parts",) else "strategies" if path == ("strategies",) else "entries"
        return [problem(f"{where}: {len(error.instance):,} {what}; at most {error.validator_value:,} are accepted",
                        "split the plan into smaller ones", "limit")]
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
    # Lines are looked up only for a problem: a JSON plan's lines cost a second pass over the text.
    parts, problems, first_at = [], [], {}
    for i, item in enumerate(data["parts"]):
        if isinstance(item, dict):
            pid = str(item["id"])
            part = Part(id=pid, name=item.get("name"), quantity=int(item.get("quantity", 1)),
                        acquire=float(item.get("acquire", 1.0)), install=float(item.get("install", 1.0)),
                        visibility=float(item.get("visibility", 1.0)), geometry=_geometry(item.get("geometry")))
        else:
            pid = str(item)
            part = Part(id=pid)
        if pid in first_at:
            first = doc.line(("parts", first_at[pid]))
            problems.append(Problem(f"duplicate part id '{pid}' (first declared at line {first})"
                                    if first else f"duplicate part id '{pid}'",
                                    "give every part a unique id; for identical units use `quantity`",
                                    file=doc.file, line=doc.line(("parts", i)), parts=(pid,), code="duplicate-part"))
            continue
        first_at[pid] = i
        parts.append(part)
    return parts, problems


def _geometry(geometry: dict | None) -> tuple | None:
    """A checked ``geometry`` mapping as the part's ``(shape, dimensions)``."""
    if geometry is None:
        return None
    (shape, dims), = geometry.items()
    if shape == "convex":
        return ("convex", tuple(tuple(tuple(float(c) for c in p) for p in body) for body in dims))
    return (str(shape), tuple(float(d) for d in dims))


def _read_strategies(data: dict, doc: Document, known: set[str],
                     unlisted_unknown: list[int] | None = None) -> tuple[list[Strategy], list[Problem]]:
    """The strategies of a plan document and the problems of their entries.  Unknown part ids past
    ``MAX_PER_KIND + 1`` are counted into ``unlisted_unknown[0]``, not built (as redundant constraints
    are: a document can name 70,000 of them)."""
    if unlisted_unknown is None:
        unlisted_unknown = [0]
    if "strategies" in data:
        entries = [(("strategies", i), s.get("name") or f"strategy {i + 1}", s.get("requires"))
                   for i, s in enumerate(data["strategies"])]
    else:
        entries = [((), DEFAULT_STRATEGY, data.get("requires"))]
    strategies, problems, names = [], [], {}
    choices: list[str] | None = None  # sorted when a suggestion is first searched for
    unknown_seen = 0  # suggestions cost O(parts) each: only the problems shown get one
    for path, name, requires in entries:
        if name in names:
            problems.append(Problem(f"two strategies are named '{name}'", "give each strategy its own name",
                                    file=doc.file, line=doc.line(path + ("name",)), code="duplicate-strategy"))
        names[name] = path
        req: dict[str, tuple[str, ...]] = {}
        weights: dict[tuple[str, str], float] = {}
        for key, before in (requires or {}).items():
            kpath = path + ("requires", key)
            key = str(key)
            if before is None:
                before = []
            elif not isinstance(before, list):
                before = [before]
            # (the common entry, a list of known ids without repeats, takes the fast paths below:
            # a document can hold 75,000 entries)
            if not all(type(b) is str for b in before):
                for b in before:  # a weighted entry {part: ID, weight: W}: the schema has checked its fields
                    if isinstance(b, dict) and b.get("weight", 1) != 1:
                        weights[(str(b["part"]), str(key))] = max(float(b["weight"]),
                                                                  weights.get((str(b["part"]), str(key)), 0.0))
                before = [str(b["part"]) if isinstance(b, dict) else str(b) for b in before]
            # Every problem of the entry is reported, and what is left of it (its known parts) still
            # takes part in the search for cycles: an unknown id does not hide a cycle.
            unknown = set()
            for pid in [key] + before if key not in known or not known.issuperset(before) else ():
                if pid not in known and pid not in unknown:
                    unknown.add(pid)
                    unknown_seen += 1
                    if unknown_seen > MAX_PER_KIND + 1:  # past the cap of _capped: counted, not built
                        continue
                    if choices is None:
                        choices = sorted(known)
                    guess = _close(pid, choices) if unknown_seen <= MAX_PER_KIND else []
                    role = "listed with requirements" if pid == key else f"in the requirements of '{key}'"
                    problems.append(Problem(
                        f"unknown part '{pid}' {role} (strategy '{name}')",
                        (f"did you mean '{guess[0]}'? " if guess else "") + "declare it under `parts` or fix the id",
                        file=doc.file, line=doc.line(kpath), parts=(pid,), code="unknown-part"))
            if key in before:
                problems.append(Problem(f"part '{key}' requires itself (strategy '{name}')",
                                        f"remove '{key}' from its own list", file=doc.file, line=doc.line(kpath),
                                        parts=(key,), code="self-requirement"))
            if len(set(before)) < len(before):
                counts = Counter(before)  # linear: a list repeating one id 100,000 times costs 100,000 steps
                for d in sorted(b for b, k in counts.items() if k > 1):
                    problems.append(Problem(f"'{key}' lists '{d}' more than once (strategy '{name}')",
                                            "list each required part once", file=doc.file, line=doc.line(kpath),
                                            parts=(key, d), severity="warning", code="repeated"))
                before = list(counts)
            if key in known:
                req[key] = tuple(b for b in before if b in known and b != key)
        strategies.append(Strategy(name=str(name), requires=req,
                                   weights={k: w for k, w in weights.items() if k[1] in req and k[0] in req[k[1]]}))
    unlisted_unknown[0] = max(0, unknown_seen - MAX_PER_KIND - 1)
    return strategies, problems


def _order_problems(ids: list[str], strategies: list[Strategy], doc: Document, *,
                    allow_cycles: bool = False) -> tuple[list[Problem], Counter, list]:
    """Cycles (unless ``allow_cycles``), duplicate or subsumed strategies, redundant constraints.

    Redundant constraints past ``MAX_PER_KIND + 1`` (the one past the cap is where the summary of
    :func:`_capped` stands) are counted, not built: the second result counts them for :func:`_capped`
    (a plan of 10,000 parts can state 100,000 redundant constraints).  The third is each
    strategy's :class:`~opportune.planning.orders.StrategyOrder` (None for a cyclic one), kept with
    the plan for its summary.  Each order covers only the parts its strategy constrains, and
    strategies are compared by their covers, so 64 strategies of 10,000 parts cost what their
    constraints cost, not 64 closures of 10,000-bit sets.
    """
    from opportune.planning.orders import CycleError, StrategyOrder

    index = {pid: i for i, pid in enumerate(ids)}
    problems: list[Problem] = []
    orders: list[StrategyOrder | None] = []
    spath = ("strategies",) if len(strategies) > 1 or "strategies" in (doc.data or {}) else ()
    redundant = 0  # the chain that implies a redundant constraint is searched for the first few only
    for si, s in enumerate(strategies):
        base = spath + (si,) if spath else ()
        pairs = [(index[b], index[a]) for b, a in s.pairs()]
        try:
            order = StrategyOrder(pairs)
            cycles = []
        except CycleError:  # the search for cycles (one per strongly connected part) only when there is one
            order, cycles = None, find_cycles(ids, s.requires, index=index)
        for cycle in cycles if not allow_cycles else ():
            arrow = " -> ".join(cycle)
            problems.append(Problem(
                f"strategy '{s.name}' has a cycle: {arrow}; an over-constrained plan has no admissible sequence",
                f"remove one of these constraints (each '{cycle[0]} -> {cycle[1]}' means '{cycle[0]}' must come before "
                f"'{cycle[1]}'), or let `opportune relax` drop the cheapest set of them",
                file=doc.file, line=doc.line(base + ("requires", cycle[1])), parts=tuple(cycle[:-1]), code="cycle"))
        orders.append(order)
        if order is None:
            continue
        local = order.local
        cover = order.covers()
        covers: dict[int, list[int]] | None = None
        local_ids: list[str] = []
        for b, a in pairs:
            if (b, a) not in cover:
                redundant += 1
                if redundant > MAX_PER_KIND + 1:
                    continue
                if redundant <= MAX_PER_KIND:
                    if covers is None:
                        covers = {}
                        for x, y in order.cover_pairs():
                            covers.setdefault(local[x], []).append(local[y])
                        local_ids = [ids[g] for g in order.support]
                    implied = " -> ".join(_path_between(order, local[b], local[a], local_ids, covers))
                else:
                    implied = "other constraints"
                problems.append(Problem(
                    f"'{ids[a]}' requires '{ids[b]}', which is already implied by {implied} (strategy '{s.name}')",
                    "the constraint is redundant: remove it, or keep it as documentation",
                    file=doc.file, line=doc.line(base + ("requires", ids[a])), parts=(ids[b], ids[a]),
                    severity="warning", code="redundant"))
    # Equal orders have equal covers (an order's transitive reduction is unique); frozensets whose
    # hashes are known and differ compare unequal at once, so 2,016 pairs of strategies cost 64 hashes.
    for o in orders:
        if o is not None:
            hash(o.covers())
    for i in range(len(strategies)):
        for j in range(i):
            oi, oj = orders[i], orders[j]
            if oi is None or oj is None:
                continue
            if oi.covers() == oj.covers():
                problems.append(Problem(
                    f"strategies '{strategies[j].name}' and '{strategies[i].name}' admit exactly the same sequences",
                    f"remove '{strategies[i].name}', it adds nothing", file=doc.file,
                    line=doc.line(spath + (i,)) if spath else None, code="duplicate-strategy"))
            elif (inside := oi.contains(oj)) or oj.contains(oi):  # each containment tested once
                small, big = (i, j) if inside else (j, i)
                problems.append(Problem(
                    f"every sequence of strategy '{strategies[small].name}' is also admitted by '{strategies[big].name}'",
                    f"'{strategies[small].name}' adds no sequences; remove it unless you keep it on purpose",
                    file=doc.file, line=doc.line(spath + (i,)) if spath else None, severity="warning",
                    code="subsumed-strategy"))
    return problems, Counter({("redundant", "warning"): max(0, redundant - MAX_PER_KIND - 1)}), orders


def _path_between(poset, b: int, a: int, ids: list[str], covers: dict[int, list[int]]) -> list[str]:
    """A chain of covers (``covers``: each element's upper covers) from b to a that is longer than the direct edge.

    A search that visits each element below ``a`` once: O(elements + covers).
    """
    prev: dict[int, int | None] = {b: None}
    stack = [b]
    while stack:
        node = stack.pop()
        for nxt in covers.get(node, ()):
            if nxt in prev or not (nxt == a or (poset.below[a] >> nxt) & 1):
                continue
            prev[nxt] = node
            if nxt == a:
                path = [a]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                if len(path) > 2:
                    return [ids[k] for k in reversed(path)]
                continue
            stack.append(nxt)
    return [ids[b], ids[a]]


def find_cycles(ids: list[str], requires, *, index: dict[str, int] | None = None) -> list[list[str]]:
    """One cycle per strongly connected component of the 'must come before' graph.

    Each cycle is a list of ids that starts and ends with the same id, e.g.
    ``['ba', 'rl', 'ba']`` (ba before rl before ba).  Linear time (Tarjan) in the constraints: a
    part in no constraint is in no cycle, so the search starts from the others only.  ``index``
    (each id's position in ``ids``), when the caller has it, saves the one pass over ``ids``
    (a plan of 64 strategies over 10,000 parts, each constraining a few hundred).

    >>> find_cycles(["a", "b", "c"], {"b": ["a"], "a": ["b"], "c": ["a"]})
    [['a', 'b', 'a']]
    """
    if index is None:
        index = {pid: i for i, pid in enumerate(ids)}
    known = index
    succ: dict[str, list[str]] = {}  # only the parts that must come before another
    for after, befores in requires.items():
        if after not in known:
            continue
        for before in befores:
            if before in known:
                succ.setdefault(before, []).append(after)
    if not succ:
        return []
    index_of, low, on_stack, stack, sccs = {}, {}, set(), [], []
    counter = 0
    for root in sorted(succ, key=index.__getitem__):  # in declaration order: the same cycles every time
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
                    work.append((nxt, iter(succ.get(nxt, ()))))
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
    for comp in sccs:
        start = min(comp, key=index.__getitem__)
        # BFS inside the component back to start: the shortest cycle through it.
        prev, frontier, found = {start: None}, [start], None
        while frontier and found is None:
            nxt_frontier = []
            for node in frontier:
                for nxt in succ.get(node, ()):
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
