"""Why an assembly has no feasible sequence under its supports and the orders asked: the parts named.

:func:`why_none` works from the ways each part can go in (:func:`opportune.derive.plan.alternatives`: a
direction, whose blockers must come after the part, and a supporter per support, which must come before
it) and the orders asked (process constraints, the base first, identical parts in order).  It collects
**necessary orders**, each with its reason, until two of them contradict each other:

* an order asked is necessary;
* when every way a part has left puts ``q`` after it (``q`` is in its way along every direction left),
  ``p`` before ``q`` is necessary; when every way left rests on ``q`` (its only supporter left),
  ``q`` before ``p`` is;
* a way that breaks a necessary order (a blocker that must come before the part, a supporter that must
  come after it) is no way: it is dropped, and the part's necessary orders are found again.

Every order found holds in every feasible sequence, so a cycle among them, or a part with no way left,
proves there is none: the message names the parts of the cycle (or the part) and why, the orders it
rests on included.  When the rules reach no contradiction (the assembly fails only through a choice
among several ways), :func:`why_none` says nothing and the caller's message stands alone.
"""

from __future__ import annotations

from collections import deque
from typing import Mapping, Sequence

#: Statements a message makes at most (the orders of a cycle and those they rest on): beyond it, "…".
MOST = 8
#: Part ids one statement names at most.
NAMED = 6

_Edges = dict[tuple[str, str], tuple[str, tuple[tuple[str, str], ...]]]


def why_none(ways: Mapping[str, Sequence], conditions=None, before: Sequence[tuple[str, str]] = ()) -> str | None:
    """The parts that make an assembly infeasible and why, or None when the necessary orders do not show it.

    Parameters
    ----------
    ways : mapping
        Each part's ways in (objects with ``name``, ``after`` and ``before``: the parts that must come after
        it, and the supporters chosen, which must come before it).
    conditions : Conditions, optional
        The supports asked (their kinds word the reasons) and the base.
    before : sequence of (str, str)
        The orders asked: ``(a, b)``, a before b.

    Returns
    -------
    str or None
        One statement a necessary order, the contradiction first; None if none was found.

    Examples
    --------
    >>> from types import SimpleNamespace as Way
    >>> ways = {"shaft": [Way(name="+x", after=frozenset(), before=frozenset())],     # a gear resting on a shaft
    ...         "gear": [Way(name="-z on shaft", after=frozenset({"shaft"}), before=frozenset({"shaft"}))]}
    >>> print(why_none(ways))      # that is in its way along its only direction
    gear must come before shaft (along -z shaft is in gear's way); shaft before gear (gear rests on or touches only shaft)
    """
    return necessary_orders(ways, conditions, before)[1]


def necessary_orders(ways: Mapping[str, Sequence], conditions=None,
                     before: Sequence[tuple[str, str]] = ()) -> tuple[dict[tuple[str, str], tuple], str | None]:
    """The orders every feasible sequence keeps, found by the rules of the module, and the contradiction
    among them if one is reached (the statement :func:`why_none` returns).

    Parameters
    ----------
    ways, conditions, before
        As :func:`why_none` takes them.

    Returns
    -------
    tuple
        ``(orders, statement)``: ``(a, b)`` → ``(reason, the orders it rests on)`` for every order found,
        ``a`` before ``b``; and the statement naming the contradiction, or None.

    Examples
    --------
    >>> from types import SimpleNamespace as Way
    >>> ways = {"a": [Way(name="+z", after=frozenset(), before=frozenset())],
    ...         "b": [Way(name="+z on a", after=frozenset(), before=frozenset({"a"}))]}
    >>> orders, statement = necessary_orders(ways)
    >>> list(orders), statement
    ([('a', 'b')], None)
    """
    edges: _Edges = {}
    for a, b in before:
        edges.setdefault((a, b), (_asked(a, b, conditions), ()))
    alive = {p: list(ws) for p, ws in ways.items()}
    for _ in range(len(alive) + 1):
        cycle = _cycle(edges)
        if cycle:
            return edges, _statements(cycle, edges)
        above, below = _reach(edges)
        grown = False
        for p in sorted(alive):
            keep = [w for w in alive[p] if not (w.after & below[p]) and not (w.before & above[p])]
            if not keep:
                return edges, _stuck(p, alive[p], edges, above, below, conditions)
            gone = [w for w in alive[p] if w not in keep]
            alive[p] = keep
            for q in sorted(frozenset.intersection(*(w.after for w in keep)) - above[p]):
                # the ways dropped that did not put q after p are part of the reason
                premises, ruled = _ruled_out(p, [w for w in gone if q not in w.after], edges, above, below, conditions)
                edges[p, q] = (f"along {_directions(w.name for w in keep)} {q} is in {p}'s way" + ruled, premises)
                grown = True
            for q in sorted(frozenset.intersection(*(w.before for w in keep)) - below[p]):
                premises, ruled = _ruled_out(p, [w for w in gone if q not in w.before], edges, above, below,
                                             conditions)
                edges[q, p] = (_only_support(p, q, conditions) + ruled, premises)
                grown = True
        if not grown:
            break
    return edges, None


def _asked(a: str, b: str, conditions) -> str:
    """Why an order asked is there."""
    if conditions is not None and getattr(conditions, "base", None) == a:
        return f"{a} is the base: it goes first"
    return "asked: a process constraint, or identical parts in order"


def _only_support(p: str, q: str, conditions) -> str:
    """``p`` rests on (or touches) ``q`` alone among what can be in before it, worded by the support's kind."""
    verb = _kind_verb(p, q, conditions)
    if verb == "resting on":
        return f"{p} can rest only on {q}"
    if verb == "touching":
        return f"{p} touches only {q} of the parts that can be in before it"
    return f"{p} rests on or touches only {q}"


def _kind_verb(p: str, q: str, conditions) -> str:
    """How ``p`` is held by ``q``: ``resting on`` (gravity), ``touching`` (connected), or both."""
    kinds = {kind for kind, n in (conditions.needs.get(p, ()) if conditions is not None else ()) if q in n}
    return "resting on" if kinds == {"gravity"} else "touching" if kinds == {"connected"} else "resting on or touching"


def _ruled_out(p: str, gone: list, edges: _Edges, above, below, conditions,
               lead: str = "; its other ways are ruled out: ") -> tuple[tuple[tuple[str, str], ...], str]:
    """Why ways of ``p`` were dropped: the orders they break (as premises) and a clause saying so (after
    ``lead``; empty if none was)."""
    premises: list[tuple[str, str]] = []
    by: dict[tuple[str, str], list[str]] = {}
    for w in gone:
        late = sorted(w.after & below[p])
        if late:
            by.setdefault((late[0], "first" if w.name == "first" else "before"), []).append(w.name)
            premises += _path(edges, late[0], p)
        else:
            early = sorted(w.before & above[p])[0]
            by.setdefault((early, "after"), []).append(w.name)
            premises += _path(edges, p, early)
    clauses = []
    for (q, side), names in by.items():
        if side == "first":     # the way of a part that may only go first (nothing holds it)
            clauses.append(f"going in first, yet {q} must come before it")
        elif side == "before":
            clauses.append(f"along {_directions(names)} {q} is in its way and must come before it")
        else:
            clauses.append(f"{_kind_verb(p, q, conditions)} {q}, which must come after it")
    return tuple(dict.fromkeys(premises)), (lead + "; ".join(clauses)) if clauses else ""


def _stuck(p: str, left: list, edges: _Edges, above, below, conditions) -> str:
    """The statement for a part with no way in left, with the orders that ruled its ways out."""
    if not left:
        needs = conditions.needs.get(p, ()) if conditions is not None else ()
        empty = [kind for kind, n in needs if not n]
        what = ("rests on no part (nothing under it touches it) and not on the fixture" if "gravity" in empty
                else "touches no other part" if "connected" in empty else "has no way in")
        return f"{p} {what}, so it can never go in"
    premises, clauses = _ruled_out(p, left, edges, above, below, conditions, lead=": ")
    return _statements([], edges, premises, lead=f"{p} has no way in{clauses}")


def _statements(cycle: list[tuple[str, str]], edges: _Edges, extra: tuple = (), lead: str | None = None) -> str:
    """The orders of a cycle (or a lead statement), then the orders they rest on, each once, at most :data:`MOST`."""
    shown: list[str] = [lead] if lead else []
    done = set()
    queue = deque(cycle + list(extra))
    first = True
    while queue:
        e = queue.popleft()
        if e in done:
            continue
        done.add(e)
        reason, premises = edges[e]
        a, b = e
        shown.append(f"{a} must come before {b} ({reason})" if first and cycle else f"{a} before {b} ({reason})")
        first = False
        queue.extend(premises)
    more = "; …" if len(shown) > MOST else ""
    return "; ".join(shown[:MOST]) + more


def _directions(names) -> str:
    """Way names as the directions they go in along, ± joined: ``+x on b``, ``-x`` → ``±x``."""
    ds = list(dict.fromkeys("going first" if n == "first" else n.split(" on ")[0] for n in names))
    out: list[str] = []
    for d in ds:
        twin = ("-" if d[0] == "+" else "+") + d[1:]
        label = "±" + d[1:] if d[0] in "+-" and twin in ds else d
        if label not in out:
            out.append(label)
    if len(out) > NAMED:
        return "every direction left to it"
    return ", ".join(out)


def _reach(edges: _Edges) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """The transitive closure of the orders: the parts after each part, and before it."""
    succ: dict[str, set[str]] = {}
    for a, b in edges:
        succ.setdefault(a, set()).add(b)
    above: dict[str, set[str]] = {}
    for a in succ:
        seen, stack = set(), list(succ[a])
        while stack:
            b = stack.pop()
            if b not in seen:
                seen.add(b)
                stack.extend(succ.get(b, ()))
        above[a] = seen
    below: dict[str, set[str]] = {}
    for a, bs in above.items():
        for b in bs:
            below.setdefault(b, set()).add(a)
    return _Default(above), _Default(below)


class _Default(dict):
    """A dict of sets whose missing keys read as empty."""

    def __missing__(self, key):
        return set()


def _path(edges: _Edges, a: str, b: str) -> list[tuple[str, str]]:
    """The orders of a shortest chain from ``a`` to ``b`` (breadth first)."""
    succ: dict[str, list[str]] = {}
    for x, y in edges:
        succ.setdefault(x, []).append(y)
    came = {a: None}
    queue = deque([a])
    while queue:
        x = queue.popleft()
        for y in succ.get(x, ()):
            if y not in came:
                came[y] = x
                queue.append(y)
    if b not in came:
        return []
    out = []
    while came[b] is not None:
        out.append((came[b], b))
        b = came[b]
    return out[::-1]


def _cycle(edges: _Edges) -> list[tuple[str, str]]:
    """A shortest cycle of the orders through a part that is after itself, as its orders (empty if none)."""
    above, _ = _reach(edges)
    best: list[tuple[str, str]] = []
    for a, b in sorted(e for e in edges if e[0] in above[e[0]]):
        back = _path(edges, b, a)
        if back and (not best or len(back) + 1 < len(best)):
            best = [(a, b)] + back
    return best
