"""Why a derived plan is as it is: each forced order with the part in the way, and what would free the most.

:func:`explain` reads a :class:`~opportune.derive.Derivation` and says

* for each strategy's constraints (its transitive reduction: every one a direct blocking), which part
  goes in along which direction, which later part would be in its way there, and what blocks the
  part's other directions;
* each part's **insertion directions**: the directions along which it goes in in at least one feasible
  sequence (a direction ``d`` of ``p`` is one iff in some strategy none of ``p``'s blockers along ``d``
  comes before it: a sequence of that strategy with ``p`` right after its predecessors has it; the
  supports, the base and the process constraints are in the strategies); the parts with one;
* for design for assembly: the number of feasible sequences (the engine's count of the plan, exact or
  a marked estimate), their share of all orders, the orders forced in every strategy, and which single
  change frees the most: a **part out of everyone's way** (the blocking relation with that part in no
  blocker set, its own constraints kept; a part of several identical instances: all of them) or a
  **direction added** (the blocking along one more direction, found in the geometry), each measured by
  deriving the plan again under the derivation's own conditions (the manifest's base, fixture,
  quantities and process constraints, the ``gravity`` and ``connected`` supports:
  :meth:`~opportune.derive.Derivation.replanned`) and counting it.

A plan written as ways has no strategies: its forced orders (each with the directions along which the
later part blocks the earlier one) and its insertion directions are read from the ways themselves
(:mod:`opportune.derive.waysfacts`), within half the time left after the plan's own count; the rest is
as above.

Every text is plain (part ids with control characters escaped, as :func:`printable` writes them).
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field, replace

import numpy as np

from opportune.derive.blocking import Blocking
from opportune.derive.manifest import ManifestError
from opportune.derive.plan import DeriveError, way_direction, way_supports
from opportune.formats.problems import CONTROL_CHARS

#: Directions tried as "one more direction" when the assembly's geometry is given: the twelve
#: diagonals between two axes (a tool tilted 45° about one axis), ``+x+y`` = (1, 1, 0)/√2.
DIAGONALS = {f"{'+' if sa > 0 else '-'}{a}{'+' if sb > 0 else '-'}{b}":
             tuple(sa / math.sqrt(2) if c == a else sb / math.sqrt(2) if c == b else 0.0 for c in "xyz")
             for a, b in ("xy", "xz", "yz") for sa in (1, -1) for sb in (1, -1)}
#: Seconds of counting for the whole explanation (shared between the plan's count and the recounts);
#: a count that does not finish in its share is an estimate, marked so.
TIME_LIMIT = 10.0
#: The relative error an estimated count stops at (a 95% interval): enough to rank the changes.
REL_ERROR = 0.05
#: Part ids a line of the report names at most (the ``--json`` form names all).
SHOWN = 6
_CONTROL = re.compile(f"[{CONTROL_CHARS}]")


def printable(text: str) -> str:
    """``text`` with every control character written as an escape (``\\x1b``), lone surrogates too.

    Parameters
    ----------
    text : str
        Any text (a part id, a plan's name).

    Returns
    -------
    str
        The same text, safe to print on a terminal: control characters and lone surrogates as their
        Python escapes, every other character kept.

    Examples
    --------
    >>> printable("gear\\x1b[2J")
    'gear\\\\x1b[2J'
    >>> printable("Zahnrad ü")
    'Zahnrad ü'
    """
    text = _CONTROL.sub(lambda m: ascii(m.group())[1:-1], text)
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


@dataclass
class Explanation:
    """What :func:`explain` found; :meth:`to_dict` is the ``--json`` form, :meth:`text` the report.

    Parameters
    ----------
    name : str
        The plan's name.
    parts : tuple of str
        The part ids.
    orders : list of dict
        Per strategy, each part's direction and its constraints, each with the direction that forces it
        and what blocks the earlier part's other directions.
    usable : dict
        Part id → its insertion directions: those along which it goes in in some feasible sequence.
    count : dict
        The feasible sequences: ``value`` (exact, or an estimate with ``exact`` False), their ``log10``
        with its interval, and their share of all orders of the parts (``share_log10``).
    forced : list of (str, str)
        The orders in every strategy.
    frees : list of dict
        The changes tried, the largest count first: a part out of everyone's way (``kind`` ``"part"``)
        or a direction added (``"direction"``), each with its count.
    unfinished : list of str
        What the time limit did not reach, in words.
    form : str
        ``"strategies"``, or ``"ways"`` for a plan written as ways: then ``orders`` is one, the forced
        orders' transitive reduction with their reasons (:mod:`opportune.derive.waysfacts`).

    Examples
    --------
    Part ``a`` is blocked by ``b`` along both directions, so it goes in first:

    >>> from opportune.derive import Derivation, plan_of
    >>> from opportune.derive.plan import exact_strategies
    >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0), "-x": (-1, 0, 0)},
    ...              {"a": {"+x": frozenset("b"), "-x": frozenset("b")}, "b": {"+x": frozenset(), "-x": frozenset()}}, 0, 0)
    >>> strategies = tuple(exact_strategies(b))
    >>> e = explain(Derivation(plan_of(b, strategies, "pin", "axes"), b, strategies, 0.0))
    >>> e.forced, e.count["value"], [(f["name"], f["count"]["value"]) for f in e.frees]
    ([('a', 'b')], 1, [('b', 2)])
    """

    name: str
    parts: tuple[str, ...]
    orders: list[dict]
    usable: dict[str, list[str]]
    count: dict
    forced: list[tuple[str, str]]
    frees: list[dict] = field(default_factory=list)
    unfinished: list[str] = field(default_factory=list)
    form: str = "strategies"

    def to_dict(self) -> dict:
        """The explanation as plain data (``derive --explain --json``).

        Returns
        -------
        dict
            The fields, with each part's single direction (where it has one), the constraints grouped by
            reason (:func:`reasons`) and every change tried: lists and dicts only, ready for JSON.

        Examples
        --------
        >>> from opportune.derive import Derivation, plan_of
        >>> from opportune.derive.plan import exact_strategies
        >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0)}, {"a": {"+x": frozenset("b")}, "b": {"+x": frozenset()}}, 0, 0)
        >>> strategies = tuple(exact_strategies(b))
        >>> doc = explain(Derivation(plan_of(b, strategies, "pin", "axes"), b, strategies, 0.0)).to_dict()
        >>> doc["single_direction"], doc["forced_in_every_strategy"], doc["reasons"][0]["before"]
        ({'a': '+x', 'b': '+x'}, [['a', 'b']], ['b'])
        """
        return {"name": self.name, "form": self.form, "parts": list(self.parts), "orders": self.orders,
                "insertion_directions": self.usable,
                "single_direction": {p: d[0] for p, d in self.usable.items() if len(d) == 1},
                "reasons": reasons(self),
                "count": self.count, "forced_in_every_strategy": [list(p) for p in self.forced],
                "frees": self.frees, "unfinished": self.unfinished}

    def text(self) -> str:
        """The explanation as a report, one statement a line (control characters escaped).

        Returns
        -------
        str
            What ``derive --explain`` prints: the forced orders with their reasons, the insertion
            directions, the count of feasible sequences and what frees the most.

        Examples
        --------
        >>> from opportune.derive import Derivation, plan_of
        >>> from opportune.derive.plan import exact_strategies
        >>> b = Blocking(("a", "b"), {"+x": (1, 0, 0)}, {"a": {"+x": frozenset("b")}, "b": {"+x": frozenset()}}, 0, 0)
        >>> strategies = tuple(exact_strategies(b))
        >>> print(explain(Derivation(plan_of(b, strategies, "pin", "axes"), b, strategies, 0.0)).text())
        pin: 2 parts, 1 strategy
        forced orders:
          b after a: along +x b would be in a's way; no other direction
        insertion directions (in some feasible sequence): a +x; b +x
        one insertion direction only (2 of 2 parts): a +x, b +x
        feasible sequences: 1 of 10^0.30 orders of the parts (1 in 10^0.30); 1 orders forced in every strategy
        frees the most: b out of everyone's way: 2 sequences (× 10^0.30)
        <BLANKLINE>
        """
        return printable("\n".join(_report(self)) + "\n")


def explain(derivation, assembly=None, *, directions: dict | None = None, time_limit: float = TIME_LIMIT,
            seed: int = 0) -> Explanation:
    """Explain a derived plan: the forced orders, the insertion directions, and what would free the most.

    Parameters
    ----------
    derivation : Derivation
        What :func:`opportune.derive.derive` returned.
    assembly : Assembly, optional
        The parts' geometry: with it, adding each direction of ``directions`` is measured too.
    directions : dict, optional
        Name → vector of the directions to try adding (default :data:`DIAGONALS`; those already used are
        left out).
    time_limit : float
        Seconds for the whole explanation but its forced orders (default :data:`TIME_LIMIT`; kept within
        a second or so past it, the longest single step): the plan's own count gets a quarter, each
        recount an equal share of what is left when it starts, and a count not finished is an estimate;
        the insertion directions and the changes to try are worked through until the time is up, the
        most blocking parts first, and what was not reached is said (``unfinished``).
    seed : int
        Seed of the estimates, if any.

    Returns
    -------
    Explanation
        Also as ``.to_dict()`` and ``.text()``.

    Examples
    --------
    >>> from opportune.derive import derive
    >>> from opportune.datasets import geometry_path
    >>> e = explain(derive(geometry_path("gearbox"), gravity="-z"))
    >>> e.count["value"], e.usable["shaft_a"], e.usable["gear_a"]
    (54054000, ['+x', '-x'], ['-x'])
    """
    end = time.perf_counter() + time_limit
    if assembly is not None:
        derivation = replace(derivation, assembly=assembly)
    block, strategies = derivation.blocking, derivation.strategies
    base = _count(derivation.plan, max(0.001, time_limit / 4), seed)
    unfinished: list[str] = []
    if derivation.plan.is_ways:
        from opportune.derive.waysfacts import ways_facts

        facts = ways_facts(derivation, until=time.perf_counter() + (end - time.perf_counter()) / 2, seed=seed)
        orders, usable, forced = [facts.order], facts.usable, facts.forced
        unfinished += facts.unfinished
    else:
        orders = [_order(block, s, getattr(derivation, "conditions", None)) for s in strategies]
        closures = [_closure(s.pairs) for s in strategies]
        forced = sorted(set.intersection(*closures)) if closures else []
        usable = {}
        earlier = [_earlier(s.pairs) for s in strategies]
        for p in block.parts:
            if time.perf_counter() > end:
                unfinished.append(f"insertion directions of {len(block.parts) - len(usable)} parts")
                break
            usable[p] = _insertion_directions(block, p, earlier)
    frees: list[dict] = []
    later = len(_new_directions(block, directions)) if assembly is not None else 0   # their share kept for them
    # the added directions' blocking is geometry, not interruptible: found only if it fits the time left, as
    # the derivation's own blocking took per direction
    cost = derivation.seconds * later / max(1, len(block.directions))
    quantities = derivation.manifest.quantities if derivation.manifest is not None else {}
    for trials in (_part_trials(block, quantities),
                   lambda: _direction_trials(derivation, directions) if assembly is not None else []):
        if not isinstance(trials, list) and time.perf_counter() + cost > end:
            if later:       # (none to add: nothing left unsaid)
                unfinished.append(f"the {later} directions to add (finding their blocking takes about {cost:.2g} s)")
            break
        trials = trials if isinstance(trials, list) else trials()
        for k, (kind, name, changed) in enumerate(trials):
            left = end - time.perf_counter()
            if left <= 0:
                unfinished.append(f"{len(trials) - k} changes to try")
                break
            pending = len(trials) - k + (later if kind == "part" else 0)
            count = _recount(derivation, changed() if callable(changed) else changed, left / pending, seed)
            frees.append({"kind": kind, "name": name, **count})
    frees.sort(key=lambda f: (-(f["count"]["log10"] if f["count"] else -math.inf), f["kind"], f["name"]))
    return Explanation(derivation.plan.name, block.parts, orders, usable, base, forced, frees, unfinished,
                       "ways" if derivation.plan.is_ways else "strategies")


def _order(block: Blocking, strategy, conditions=None) -> dict:
    """One strategy's constraints, each with its reason: the earlier part's direction, the later part in its way
    there, and the earlier part's other directions with their blockers."""
    pairs = []
    for before, after in strategy.pairs:
        if before in way_supports(strategy.directions[after]):      # after rests on (or touches) before
            kinds = {k for k, n in (conditions.needs.get(after, ()) if conditions is not None else ()) if before in n}
            verb = {frozenset({"gravity"}): "resting on", frozenset({"connected"}): "touching"}.get(
                frozenset(kinds), "resting on or touching")
            pairs.append({"before": before, "after": after, "direction": None, "support": verb,
                          "other_directions": {}})
            continue
        d = way_direction(block, before, strategy.directions[before])
        others = {k: sorted(q) for k, q in block.blockers[before].items() if k != d}
        pairs.append({"before": before, "after": after, "direction": d, "other_directions": others})
    return {"directions": {p: way_direction(block, p, w) for p, w in strategy.directions.items()},
            "constraints": pairs}


def _insertion_directions(block: Blocking, part: str, earlier: list[dict[str, set[str]]]) -> list[str]:
    """The directions along which ``part`` goes in in some feasible sequence.  With the plan's strategies
    (``earlier``: each one's parts before each part): those whose blockers are all outside the part's
    predecessors in some strategy, as a sequence of that strategy placing the part right after them has it
    (exact with supports, a base and process constraints too, the plan admitting exactly the feasible
    sequences); without: :func:`_usable`'s peeling of the blocking relation."""
    if not earlier:
        return [d for d in block.directions if _usable(block, part, d)]
    own = block.blockers[part]      # (a direction the fixture is in the part's way along is none for it)
    return [d for d in block.directions if d in own and any(not (own[d] & e.get(part, set())) for e in earlier)]


def _earlier(pairs) -> dict[str, set[str]]:
    """The parts before each part in an order (its pairs' closure)."""
    out: dict[str, set[str]] = {}
    for a, b in _closure(pairs):
        out.setdefault(b, set()).add(a)
    return out


def _usable(block: Blocking, part: str, direction: str) -> bool:
    """Whether ``part`` goes in along ``direction`` in some feasible sequence: the relation with ``part`` held
    to that direction lets every part out, last first (:func:`~opportune.derive.plan.locked`'s peeling, with a
    count of the blockers left per part and direction: O(parts × directions + the blocker sets' sizes))."""
    waiting: dict[str, list[tuple[str, str]]] = {}   # blocker -> the (part, direction) it blocks
    left: dict[tuple[str, str], int] = {}
    for p, dirs in block.blockers.items():
        for d, q in dirs.items():
            if p == part and d != direction:
                continue
            left[p, d] = len(q)
            for b in q:
                waiting.setdefault(b, []).append((p, d))
    free = [p for p, d in left if left[p, d] == 0]
    out = set()
    while free:
        p = free.pop()
        if p in out:
            continue
        out.add(p)
        for key in waiting.get(p, ()):
            left[key] -= 1
            if left[key] == 0 and key[0] not in out:
                free.append(key[0])
    return len(out) == len(block.parts)


def _closure(pairs) -> set[tuple[str, str]]:
    """Every ``(before, after)`` an order's pairs imply."""
    after: dict[str, set[str]] = {}
    for a, b in pairs:
        after.setdefault(a, set()).add(b)
    out = set()
    for a in after:
        stack, seen = list(after[a]), set()
        while stack:
            b = stack.pop()
            if b not in seen:
                seen.add(b)
                stack.extend(after.get(b, ()))
        out |= {(a, b) for b in seen}
    return out


def _count(plan, seconds: float, seed: int) -> dict:
    """The plan's feasible sequences (the engine's count), with their share of all orders of its parts."""
    from opportune.engine import Schedule

    r = Schedule(plan).count_result(time_limit=seconds, seed=seed, rel_error=REL_ERROR)
    n = len(plan.parts)
    log_all = math.lgamma(n + 1) / math.log(10)
    low, high = r.interval_log10 or (r.log10, r.log10)
    return {"value": r.value if r.exact else float(r.value), "exact": r.exact, "log10": r.log10,
            "log10_low": low, "log10_high": high, "log10_all_orders": log_all, "share_log10": r.log10 - log_all}


def _part_trials(block: Blocking, quantities: dict | None = None) -> list[tuple[str, str, object]]:
    """The changed blocking relations to recount, each made when asked for (a function of none): each part out
    of everyone's way (a part of several identical instances, ``quantities``: all of them, named by the part),
    those that block the most part-directions first."""
    out = []
    blocks = {q: 0 for q in block.parts}
    for dirs in block.blockers.values():
        for s in dirs.values():
            for q in s:
                blocks[q] += 1
    group = {i: part for part, instances in (quantities or {}).items() for i in instances}
    members: dict[str, set[str]] = {}
    for q in block.parts:
        members.setdefault(group.get(q, q), set()).add(q)
    for name in sorted(members, key=lambda n: -sum(blocks[q] for q in members[n])):
        gone = members[name]
        if not sum(blocks[q] for q in gone):
            continue
        out.append(("part", name, lambda gone=gone: _without(block, gone)))
    return out


def _without(block: Blocking, gone: set[str]) -> Blocking:
    """The blocking relation with the parts ``gone`` in no blocker set (made when its recount's turn comes:
    O(parts × directions) each, seconds for all the parts of a 300-part block)."""
    return replace(block, blockers={p: {d: s - gone for d, s in dirs.items()} for p, dirs in block.blockers.items()})


def _new_directions(block: Blocking, directions: dict | None) -> dict:
    """The directions to try adding (default :data:`DIAGONALS`) that the relation does not have yet."""
    used = {tuple(np.round(np.asarray(v, float) / np.linalg.norm(v), 9)) for v in block.directions.values()}
    return {name: vec for name, vec in (DIAGONALS if directions is None else directions).items()
            if name not in block.directions
            and tuple(np.round(np.asarray(vec, float) / np.linalg.norm(vec), 9)) not in used}


def _direction_trials(derivation, directions: dict | None) -> list[tuple[str, str, Blocking]]:
    """The changed blocking relations to recount: each direction added, its blocking found in the geometry
    (the fixture in place, as the derivation had it)."""
    block, out = derivation.blocking, []
    if derivation.assembly is not None:
        tried = _new_directions(block, directions)
        more = derivation.blocking_along(tried) if tried else None   # one pass for all of them
        for name, vec in tried.items():
            blockers = {p: {**dirs, **({name: more.blockers[p][name]} if name in more.blockers[p] else {})}
                        for p, dirs in block.blockers.items()}
            out.append(("direction", name, replace(block, blockers=blockers,
                                                     directions={**block.directions, name: vec})))
    return out


def _recount(derivation, block: Blocking, seconds: float, seed: int) -> dict:
    """Derive the plan of a changed blocking relation again, under the derivation's conditions, and count
    it (or say why not)."""
    try:
        plan = derivation.replanned(block)
    except (DeriveError, ManifestError) as exc:
        return {"count": None, "why": str(exc)}
    return {"count": _count(plan, seconds, seed)}


def _number(count: dict) -> str:
    """A count as the report writes it: exact digits up to 12, else powers of ten; estimates marked."""
    if count["exact"] and count["log10"] < 12:
        return f"{int(count['value']):,}"
    return ("" if count["exact"] else "about ") + f"10^{count['log10']:.2f}"


def _names(parts, most: int = SHOWN) -> str:
    """Part ids joined, at most ``most`` of them (then how many more)."""
    parts = list(parts)
    more = f", … ({len(parts) - most} more)" if len(parts) > most else ""
    return ", ".join(parts[:most]) + more


def _directions(dirs: dict[str, list[str]]) -> str:
    """``{"+x": [a], "-x": [a], "+y": []}`` as ``±x by a; +y free``: equal blockers grouped, ± joined."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for d, q in dirs.items():
        groups.setdefault(tuple(q), []).append(d)
    out = []
    for q, ds in groups.items():
        names = []
        for d in ds:
            twin = ("-" if d[0] == "+" else "+") + d[1:]
            if d[0] in "+-" and twin in ds:
                if d[0] == "+":
                    names.append("±" + d[1:])
            else:
                names.append(d)
        out.append(", ".join(names) + (" by " + _names(q) if q else " free"))
    return "; ".join(out)


def reasons(e: Explanation) -> list[dict]:
    """The constraints of every strategy grouped by their reason: a part going in along a direction before the
    parts that would be in its way there, with the strategies that make that choice.

    Parameters
    ----------
    e : Explanation
        An explanation.

    Returns
    -------
    list of dict
        ``{"part", "direction", "before", "other_directions", "strategies"}`` each (strategies from 1); a
        support (the later parts rest on or touch the part; ``direction`` None) has ``"support"``: ``resting
        on``, ``touching`` or ``resting on or touching``.

    Examples
    --------
    >>> from opportune.derive import derive
    >>> r = reasons(explain(derive("geometry:gearbox")))
    >>> next(x["before"] for x in r if x["part"] == "cover" and x["direction"] == "+x")
    ['screw_1', 'screw_2', 'screw_3', 'screw_4']
    """
    grouped: dict[tuple, dict] = {}
    for k, order in enumerate(e.orders, 1):
        for c in order["constraints"]:
            support = {"support": c["support"]} if c.get("support") else {}
            support.update({"why": c["why"]} if c.get("why") else {})
            r = grouped.setdefault((c["before"], c["direction"], c.get("support"), c.get("why")), {
                "part": c["before"], "direction": c["direction"], **support, "before": [],
                "other_directions": c["other_directions"], "strategies": []})
            if c["after"] not in r["before"]:
                r["before"].append(c["after"])
            if k not in r["strategies"]:
                r["strategies"].append(k)
    return list(grouped.values())


def _report(e: Explanation) -> list[str]:
    """The lines of :meth:`Explanation.text`."""
    n = len(e.orders)
    form = f"{n} strateg{'y' if n == 1 else 'ies'}" if e.form == "strategies" else "written as each part's ways in"
    lines = [f"{e.name}: {len(e.parts)} parts, {form}", "forced orders:"]
    for r in reasons(e):
        where = "" if len(r["strategies"]) == n else " (strateg" + ("y s" if len(r["strategies"]) == 1 else "ies s") \
            + ", s".join(map(str, r["strategies"])) + ")"
        if r.get("why"):                # forced by the ways together, not by one blocking or support
            lines.append(f"  {_names(r['before'])} after {r['part']}: {r['why']}")
            continue
        if r["direction"] is None:      # a support: the later parts rest on (or touch) the earlier one
            lines.append(f"  {_names(r['before'])} after {r['part']}{where}: "
                         f"{r.get('support', 'resting on or touching')} {r['part']}")
            continue
        lines.append(f"  {_names(r['before'])} after {r['part']}{where}: along {r['direction']} "
                     f"{_names(r['before'])} would be in {r['part']}'s way; "
                     f"{_directions(r['other_directions']) or 'no other direction'}")
    single = {p: d[0] for p, d in e.usable.items() if len(d) == 1}
    lines.append("insertion directions (in some feasible sequence): "
                 + "; ".join(f"{p} {' '.join(d)}" for p, d in e.usable.items()))
    lines.append(f"one insertion direction only ({len(single)} of {len(e.parts)} parts): "
                 + (", ".join(f"{p} {d}" for p, d in single.items()) or "none"))
    c = e.count
    lines.append(f"feasible sequences: {_number(c)} of 10^{c['log10_all_orders']:.2f} orders of the parts "
                 f"(1 in 10^{max(0.0, -c['share_log10']):.2f}); {len(e.forced)} orders forced in every "
                 + ("strategy" if e.form == "strategies" else "feasible sequence"))
    if e.unfinished:
        lines.append("not reached within the time limit: " + "; ".join(e.unfinished))
    best = next((f for f in e.frees if f["count"]), None)
    if best is None:
        lines.append("frees the most: nothing tried within the time limit" if e.unfinished else
                     "frees the most: nothing to try (no part is in another's way)")
    else:
        what = (f"{best['name']} out of everyone's way" if best["kind"] == "part" else
                f"the direction {best['name']} added")
        gain = best["count"]["log10"] - c["log10"]
        lines.append(f"frees the most: {what}: {_number(best['count'])} sequences (× 10^{gain:.2f})")
        for f in e.frees[1:4]:
            if f["count"]:
                lines.append(f"  next: {f['kind']} {f['name']}: {_number(f['count'])}")
    return lines
