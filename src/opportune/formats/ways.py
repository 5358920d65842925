"""Plans written as ways: each part's ways in, the compact form exact for any number of alternatives.

A plan file may give, instead of ``requires`` or ``strategies``, each part's ways in::

    parts: [base, peg, cap]
    ways:
      peg:                        # either way; a part not listed goes in at any time
        - {name: +z, blockers: [cap], after: [base]}
        - {name: -x, needs: [[base, cap]]}
      cap:
        - {after: [base]}

A sequence is admissible iff each part, when it goes in, has a way none of whose ``blockers`` is in yet,
all of whose ``after`` parts are in, and each of whose ``needs`` (lists of parts) has at least one part
in.  So a plan of one strategy is the special case of one way per part, its ``after`` the part's
required parts (:func:`ways_of_strategy`); a union of strategies is not in general (the choice of a
strategy binds all parts at once, a way binds one), nor is a plan of ways in general a union of few
partial orders: a plan derived from geometry whose parts have several incomparable ways each needs
more partial orders than a plan holds, and one way list per part (:mod:`opportune.derive.plan`).

Identical parts: a part of quantity ``q`` has ``q`` units that go in one after another (as in a plan of
strategies); ``id#k`` names its ``k``-th unit, as a key (that unit's ways; the key ``id``: every unit's)
and in a way; a bare ``id`` of such a part is its first unit among ``blockers`` and ``needs`` (any unit
in) and its last among ``after`` (every unit in).  So the units of a derived plan's identical instances
keep each instance's own ways, and a look names the part, any of its units.

Limits (:mod:`opportune.limits`): at most :data:`~opportune.limits.MAX_WAYS` ways per part and
:data:`~opportune.limits.MAX_CONSTRAINTS` part ids in all the ways of a plan, checked before anything
else is built; and the plan must have an admissible sequence, searched for
within :data:`SEARCH_WORK` sets and :data:`SEARCH_SECONDS` (a plan not decided within them is accepted
with a warning).
"""

from __future__ import annotations

import time

from opportune.formats.documents import Document
from opportune.formats.problems import Problem, closest
from opportune.limits import MAX_CONSTRAINTS, MAX_WAYS
from opportune.planning.plan import Part, Plan, Strategy, Way
from opportune.planning.ways import UNIT, Undecided, WaysTable, unit_id

__all__ = ["SEARCH_WORK", "WAYS_POLICIES", "check_ways", "not_for_ways", "ways_of_strategy", "ways_plan"]

#: The policies and study strategies that take a plan written as ways (the others read the orders of
#: strategies): the one list every door checks (``replay``, ``simulate``, ``evaluate``, a study's settings,
#: the service's runs).
WAYS_POLICIES = ("lookahead", "paper", "bin-first", "slack", "rollout", "optimal", "pallet", "shake", "kitting",
                 "buffer", "quantify", "random")

#: Most sets the check of a plan of ways visits looking for an admissible sequence (a plan with one is
#: found in as many sets as it has parts as a rule: each set not taken is proved dead first).
SEARCH_WORK = 20_000
#: Seconds the check's search may take at most, whatever the plan's size (10,000 parts of 256 ways each
#: make a set cost seconds): past them the plan is accepted with a warning.
SEARCH_SECONDS = 2.0


def _ids(value) -> list[str]:
    return [str(v) for v in (value or [])]


def check_ways(data: dict, doc: Document, parts: list[Part]) -> tuple[dict[str, tuple[Way, ...]], list[Problem]]:
    """Read and check the ``ways`` of a schema-valid document.

    Parameters
    ----------
    data : dict
        The plan document (schema-valid: ``ways`` maps part ids to lists of ways).
    doc : Document
        Where it was read from (for the problems' lines).
    parts : list of Part
        The plan's parts.

    Returns
    -------
    tuple of (dict, list of Problem)
        Each listed part's ways, and every problem found (errors leave the ways unusable).

    Examples
    --------
    >>> import time

from opportune.formats.documents import Document
    >>> data = {"parts": ["a", "b"], "ways": {"b": [{"blockers": ["a", "c"]}]}}
    >>> ways, problems = check_ways(data, Document(data, {}, "f.yaml"), [Part("a"), Part("b")])
    >>> [p.message for p in problems]
    ["unknown part 'c' in way 1 of 'b'"]
    """
    file = doc.file
    problems: list[Problem] = []
    for key in ("requires", "strategies", "assemblies"):
        if key in data:
            return {}, [Problem(f"the plan has both `{key}` and `ways`", "give the order one way: as partial "
                                "orders (`requires`, `strategies`), an AND/OR graph (`assemblies`) or each part's "
                                "ways in (`ways`)", file=file, line=doc.line((key,)), code="conflict")]
    known = {p.id: p.quantity for p in parts}
    raw = data["ways"] or {}
    total = sum(len(_ids(w.get("blockers"))) + len(_ids(w.get("after"))) + sum(len(n) for n in w.get("needs") or ())
                for ws in raw.values() for w in ws)
    if total > MAX_CONSTRAINTS:
        return {}, [Problem(f"the ways name {total:,} parts in all; at most {MAX_CONSTRAINTS:,} are accepted",
                            "split the plan", file=file, line=doc.line(("ways",)), code="limit")]
    out: dict[str, tuple[Way, ...]] = {}
    for key, ways in raw.items():
        pid = str(key)
        if _unit(pid, known) is None:
            problems.append(_unknown(pid, "listed with ways", known, file, doc.line(("ways", key))))
            continue
        if len(ways) > MAX_WAYS:
            problems.append(Problem(f"'{pid}' has {len(ways):,} ways; at most {MAX_WAYS:,} are accepted",
                                    "keep the ways whose blockers and needs no other way's are inside",
                                    file=file, line=doc.line(("ways", key)), parts=(pid,), code="limit"))
            continue
        read = [_way(pid, i, w, known, doc, problems) for i, w in enumerate(ways)]
        out[pid] = tuple(w for w in read if w is not None)
    return out, problems


def _unit(ref: str, known: dict[str, int]) -> tuple[str, int] | None:
    """``(part, unit number or 0 for the part itself)`` of a reference ``id`` or ``id#k``; None if the plan has
    no such part or unit."""
    if ref in known:
        return ref, 0
    pid, sep, k = ref.rpartition(UNIT)
    if sep and pid in known and k.isdigit() and 1 <= int(k) <= known[pid] and known[pid] > 1 and k[0] != "0":
        return pid, int(k)
    return None


def _units(refs: list[str], known: dict[str, int], last: bool) -> list[str]:
    """References as units: a bare id of a part of several is its first unit (its last, ``last``)."""
    return [unit_id(q, known[q] if last else 1) if known.get(q, 1) > 1 else q for q in refs]


def _way(pid: str, i: int, entry: dict, known: dict[str, int], doc: Document, problems: list[Problem]) -> Way | None:
    """One way of part (or unit) ``pid`` (its ``i``-th), or None with its problems appended."""
    line = doc.line(("ways", pid, i))
    blockers, after = _ids(entry.get("blockers")), _ids(entry.get("after"))
    needs = [_ids(n) for n in entry.get("needs") or ()]
    bad = False
    for q in dict.fromkeys(blockers + after + [q for n in needs for q in n]):
        if _unit(q, known) is None:
            problems.append(_unknown(q, f"in way {i + 1} of '{pid}'", known, doc.file, line))
            bad = True
        elif q == pid or (q in known and _unit(pid, known)[0] == q) or (pid in known and _unit(q, known)[0] == pid):
            problems.append(Problem(f"way {i + 1} of '{pid}' names '{pid}' itself", f"remove '{pid}' from its own way",
                                    file=doc.file, line=line, parts=(pid,), code="self-requirement"))
            bad = True
    if set(blockers) & set(after):
        both = sorted(set(blockers) & set(after))
        problems.append(Problem(f"way {i + 1} of '{pid}' has {', '.join(both)} both among its blockers and after it: "
                                "it never admits the part", "remove the way, or the part from one list",
                                file=doc.file, line=line, parts=(pid, *both), code="ways-contradiction"))
        bad = True
    if bad:
        return None
    blockers, after = _units(blockers, known, False), _units(after, known, True)
    needs = [_units(n, known, False) for n in needs]
    return Way(frozenset(blockers), tuple(frozenset([q]) for q in after) + tuple(frozenset(n) for n in needs),
               name=entry.get("name"), first=bool(entry.get("first", False)))


def _unknown(pid: str, role: str, known: set[str], file, line) -> Problem:
    guess = closest(pid, sorted(known))
    return Problem(f"unknown part '{pid}' {role}",
                   (f"did you mean '{guess}'? " if guess else "") + "declare it under `parts` or fix the id",
                   file=file, line=line, parts=(pid,), code="unknown-part")


def feasibility_problems(plan: Plan, doc: Document) -> list[Problem]:
    """An error if the plan of ways admits no sequence at all, a warning if the search for one ran out
    of work (:data:`SEARCH_WORK` sets) first.

    Parameters
    ----------
    plan : Plan
        A plan written as ways.
    doc : Document
        Where it was read from.

    Returns
    -------
    list of Problem
        Empty when an admissible sequence was found.

    Examples
    --------
    >>> import time

from opportune.formats.documents import Document
    >>> plan = Plan("p", (Part("a"), Part("b")), (), ways={"a": (Way(frozenset("b")),), "b": (Way(frozenset("a")),)})
    >>> [p.code for p in feasibility_problems(plan, Document({}, {}, None))]
    ['ways-infeasible']
    """
    table = WaysTable.of(plan)
    try:
        found = table.completion(0, SEARCH_WORK, time.perf_counter() + SEARCH_SECONDS)
    except Undecided:
        return [Problem(f"no admissible sequence found within {SEARCH_WORK:,} sets or {SEARCH_SECONDS:g} s of "
                        "search (nor proof that there is none)", "count the plan: a count of 0 means no sequence is admissible",
                        file=doc.file, line=doc.line(("ways",)), severity="warning", code="ways-undecided")]
    if found is not None:
        return []
    units = [p.id for p in plan.parts for _ in range(p.quantity)]
    first = list(dict.fromkeys(units[i] for i in range(table.n) if table.can_go(0, i)))
    why = (f"parts that can go in first: {', '.join(first[:12])}{', …' if len(first) > 12 else ''}" if first
           else "no part can go in first")
    return [Problem(f"the ways admit no sequence: whatever goes in first, some part can never go in ({why})",
                    "check the blockers and needs of each part's ways", file=doc.file, line=doc.line(("ways",)),
                    code="ways-infeasible")]


def ways_of_strategy(plan: Plan, strategy: int = 0) -> Plan:
    """A plan of strategies written as ways: exact for one strategy (the special case of ways).

    Each part gets one way whose ``after`` is the part's required parts in the strategy (each one's last
    unit; the plan's other strategies are ignored: a union of strategies is not per-part).

    Parameters
    ----------
    plan : Plan
        A plan with strategies.
    strategy : int, default 0
        The strategy written.

    Returns
    -------
    Plan
        The same parts, the strategy as ways: it admits exactly the strategy's sequences.

    Examples
    --------
    >>> from opportune.formats.loader import make_plan
    >>> ways_of_strategy(make_plan(["a", "b"], {"b": ["a"]})).to_dict()["ways"]
    {'b': [{'after': ['a']}]}
    >>> ways_of_strategy(make_plan([{"id": "a", "quantity": 2}, "b"], {"b": ["a"]})).to_dict()["ways"]
    {'b': [{'after': ['a#2']}]}
    """
    s: Strategy = plan.strategies[strategy]
    q = {p.id: p.quantity for p in plan.parts}
    ways = {pid: (Way(frozenset(), tuple(frozenset([unit_id(b, q[b]) if q[b] > 1 else b]) for b in before)),)
            for pid, before in s.requires.items() if before}
    return ways_plan(plan.name, plan.parts, ways, description=plan.description)


def ways_plan(name: str, parts, ways, *, description: str | None = None, simulation=None,
              source: str | None = None) -> Plan:
    """A plan written as ways, built directly (no file check: the caller's ways name its parts only).

    Parameters
    ----------
    name : str
        The plan's name.
    parts : iterable of Part
        The parts.
    ways : mapping of str to iterable of Way
        Each part's (or unit's, ``id#k``) ways (a part not listed: one free way), naming units
        ``id#k`` of the parts of several (:meth:`~opportune.planning.ways.WaysTable.of`).
    description : str, optional
        Text for people.
    simulation : mapping, optional
        The cell's settings.
    source : str, optional
        The file it was read from.

    Returns
    -------
    Plan
        The plan, with no strategies.

    Examples
    --------
    >>> ways_plan("p", [Part("a")], {}).is_ways
    True
    """
    return Plan(name=name, parts=tuple(parts), strategies=(), source=source, description=description,
                simulation=simulation or {}, ways={k: tuple(v) for k, v in ways.items()})


def not_for_ways(what: str) -> str:
    """The refusal of a command (or policy) that does not take plans written as ways yet.

    Parameters
    ----------
    what : str
        The command or policy, as the user named it.

    Returns
    -------
    str
        The message: what does take such a plan.

    Examples
    --------
    >>> not_for_ways("graph").split(":")[0]
    'graph does not take a plan written as ways yet'
    """
    return (f"{what} does not take a plan written as ways yet: check, count, replay, simulate, evaluate and the "
            f"Sequencer do, with the policies and strategies {', '.join(WAYS_POLICIES)}")
