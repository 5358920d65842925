"""Where the fallback loses to the optimum: the looks on its own path at which the default policy without
its optimum (``Lookahead(optimal=False)``: the frontier window) acts otherwise than the optimum, each with
how often its run meets that look and what its action costs there (the optimum's expected cost after the
fallback's action, less after the optimum's: its *advantage*).  The terms sum to the fallback's gap
exactly; the largest say which decisions to look at.

The uniform bin: states as the optimum keeps them (the buffer as counts per part: the fallback is asked
with the buffer in declaration order).  The pile bin (``--bin pile``): states as the fallback's evaluation
keeps them, each with the look it sees (the pile's top stays until a unit is taken), the optimum's values
asked of the pile's programme; the fallback's own expected time is summed along the same path, so the
terms are checked against it.  A lab plan by its name (``--size``, ``--plan``, the lab's seed-0 plans),
the setting by ``--visible`` and ``--capacity``::

    python benchmarks/fallback_diagnosis.py --size 16 --plan r20-16x2 --visible 1 --capacity 1
    python benchmarks/fallback_diagnosis.py --size 16 --plan r2-16x2 --visible 2 --capacity 2 --bin pile
"""

from __future__ import annotations

import argparse
import heapq
import sys
from pathlib import Path

from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.policies.optimal import optimal_solver, same_action
from opportune.policies.pile import PileSolver, pile_solver

sys.path.insert(0, str(Path(__file__).resolve().parent))
from policy_lab import generate  # noqa: E402  (the lab's plans, by name)


def _level(key: tuple) -> int:
    """Every move raises it (an installation by 2 and a buffered unit by 1, one taken from the buffer by 1):
    the states in this order come after every state that leads to them."""
    return 2 * key[0].bit_count() + sum(key[2])


def differences(engine, visible: int, capacity: int | None) -> tuple[float, float, list[dict]]:
    """The optimum's value, the fallback's gap as the sum of its terms, and every look on the fallback's path
    where the two act differently: ``looks`` (how many times the fallback's run meets that state and look, on
    average), ``advantage`` (the optimum's cost after the fallback's action less after its own), the state
    and the two actions.  The terms sum to the fallback's value less the optimum's, exactly (each look's
    advantage, summed over the fallback's run, telescopes)."""
    optimum = optimal_solver(engine, visible=visible, capacity=capacity, merge=False)
    best = optimum.value()
    fallback = Lookahead(optimal=False, visible=visible, capacity=capacity)
    ev = PolicyEvaluator(engine, fallback, visible=visible, capacity=capacity)      # its looks
    start = optimum.start_key()
    reach, todo, out, gap = {start: 1.0}, [(0, start)], [], 0.0
    while todo:
        _, key = heapq.heappop(todo)
        r = reach.pop(key)
        if key[0] == engine.full:
            continue
        looks = ev._looks(ev._bin_counts(key))
        buffer = tuple(ev.ids[i] for i, c in enumerate(key[2]) for _ in range(c))
        free = float("inf") if capacity is None else capacity - len(buffer)
        theirs = fallback.choose_looks(engine, key[0], key[1], buffer, free,
                                       [tuple(ev.ids[i] for i in look) for look, _ in looks])
        p_shake = sum(p for (_, p), a in zip(looks, theirs) if a.kind == "shake")
        for (look, p), other in zip(looks, theirs):
            n = r * p / (1.0 - p_shake)         # looks like this one the fallback's run meets here, on average
            mine, cost = optimum.best_action(key, look)
            nxt = None if other.kind == "shake" else next(
                (c, k) for c, k, a in optimum.policy_moves(key, look) if same_action(a, other))
            after = optimum.costs.shake + optimum.value(key) if nxt is None else nxt[0] + optimum.value(nxt[1])
            if not same_action(mine, other):
                gap += n * (after - cost)
                out.append({"looks": n, "advantage": after - cost, "installed": key[0].bit_count(),
                            "buffer": buffer, "look": tuple(ev.ids[i] for i in look), "optimum": str(mine),
                            "fallback": str(other), "strategies": key[1]})
            if nxt is not None:
                if nxt[1] not in reach:
                    heapq.heappush(todo, (_level(nxt[1]), nxt[1]))
                reach[nxt[1]] = reach.get(nxt[1], 0.0) + r * p / (1.0 - p_shake)
    return best, gap, out


def _pile_level(ev, key: tuple) -> int:
    """As :func:`_level`, for the keys of the fallback's evaluation (the buffer ordered or as counts)."""
    return 2 * key[0].bit_count() + (len(key[2]) if ev.ordered else sum(key[2]))


def _pile_q(optimum, key: tuple, look: tuple[int, ...], action) -> float:
    """The optimum's expected cost after ``action`` on ``look`` at its ``key`` (a shake: a fresh pile)."""
    if action is None or action.kind == "shake":
        return optimum.costs.shake + optimum._shake_value(key)
    for cost, nxt, move in optimum._moves(key, look):
        if same_action(move, action):
            return cost + optimum._after(key, look, move, nxt)
    raise ValueError(f"{action} is not a move of the optimum's at this state")


def _pile_next(ev, key: tuple, look: tuple[int, ...], move) -> list[tuple[tuple, float]]:
    """The looks after the fallback's move (a unit taken from the top is replaced by a hidden one, each
    drawn as its count says; an installation from the buffer leaves the top), with their chances."""
    cost, nxt, action = move
    if action.kind == "install" and action.source == "buffer":
        return [(look, 1.0)]
    rest = list(look)
    rest.remove(ev.plan.index(action.part))
    hidden = [c - look.count(j) for j, c in enumerate(ev._bin_counts(key))]
    total = sum(hidden)
    if not total:
        return [(tuple(sorted(rest)), 1.0)]
    return [(tuple(sorted(rest + [j])), c / total) for j, c in enumerate(hidden) if c]


def pile_differences(engine, visible: int, capacity: int | None,
                     fallback=None) -> tuple[float, float, float, list[dict]]:
    """:func:`differences` in the pile bin: the optimum's value, the fallback's value summed along its
    path, the gap as the sum of its terms, and the looks where the two act differently.  A look is met
    fresh (after a shake: the bin's units drawn) or after a move (the top less the unit taken, one drawn);
    each state's looks are taken once all that leads to it is summed (every move raises :func:`_pile_level`).
    ``fallback``: the policy diagnosed (default: the look-ahead with its optimum switched off)."""
    settings = dict(visible=visible, capacity=capacity, max_states=10 ** 9)
    optimum = pile_solver(engine, **settings)
    best = optimum.value()
    if fallback is None:
        fallback = Lookahead(optimal=False, visible=visible, capacity=capacity, bin="pile")
    ev = PileSolver(engine, fallback, **settings)
    start = ev.policy_start()
    fresh, arrived, todo = {start: 1.0}, {}, [(0, start)]
    value = gap = 0.0
    out = []
    while todo:
        _, key = heapq.heappop(todo)
        f, came = fresh.pop(key, 0.0), arrived.pop(key, {})
        if key[0] == engine.full:
            continue
        okey = optimum.policy_key(key[0], key[1], ev._buffered(key))
        moves = {look: ev._policy_move(fallback, key, look) for look in came}
        f += sum(m for look, m in came.items() if moves[look] is None)     # a shake: a fresh pile here
        mass = dict(came)
        if f:           # the fresh looks, where a shake or the start leads here (else none is met)
            drawn = list(ev._looks(ev._bin_counts(key)))
            for look, _ in drawn:
                if look not in moves:
                    moves[look] = ev._policy_move(fallback, key, look)
            acted = sum(p for look, p in drawn if moves[look] is not None)
            if acted <= 1e-15:
                raise RuntimeError("the fallback shakes at every look of a state it reaches: it never finishes")
            for look, p in drawn:
                mass[look] = mass.get(look, 0.0) + f * p / acted
        for look, m in mass.items():
            move = moves[look]
            value += m * (optimum.costs.look + (optimum.costs.shake if move is None else move[0]))
            mine = optimum.best_action(okey, look)[0]
            theirs = None if move is None else move[2]
            q_best = _pile_q(optimum, okey, look, mine)
            advantage = _pile_q(optimum, okey, look, theirs) - q_best
            if advantage > 1e-12:
                gap += m * advantage
                out.append({"looks": m, "advantage": advantage, "installed": key[0].bit_count(),
                            "buffer": ev._buffered(key), "look": tuple(ev.ids[i] for i in look),
                            "optimum": str(mine), "fallback": "shake" if theirs is None else str(theirs),
                            "strategies": key[1], "fresh": look not in came})
            if move is None:
                continue
            nxt = move[1]
            if nxt not in fresh and nxt not in arrived:
                heapq.heappush(todo, (_pile_level(ev, nxt), nxt))
            into = arrived.setdefault(nxt, {})
            for after, p in _pile_next(ev, key, look, move):
                into[after] = into.get(after, 0.0) + m * p
    return best, value, gap, out


def split(rows: list[dict], by) -> list[tuple]:
    """The terms summed by ``by(row)`` (the units installed, the strategies open, ...), in its order."""
    out: dict = {}
    for row in rows:
        out[by(row)] = out.get(by(row), 0.0) + row["looks"] * row["advantage"]
    return sorted(out.items())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", required=True, help="the lab's plans of this many parts, or its group of LOW-HIGH parts (8-12)")
    ap.add_argument("--plan", required=True, help="the plan's name in the lab (r20-16x2, ...)")
    ap.add_argument("--visible", type=int, default=1)
    ap.add_argument("--capacity", default="1", help="buffer locations (inf: unlimited)")
    ap.add_argument("--top", type=int, default=8, help="the largest terms shown")
    ap.add_argument("--bin", choices=("uniform", "pile"), default="uniform")
    args = ap.parse_args(argv)
    lo, _, hi = args.size.partition("-")
    plans = {plan.name: plan for plan, _ in generate(0, 30, int(lo), int(hi or lo))}
    if args.plan not in plans:
        ap.error(f"--plan: none named {args.plan!r} of {args.size} parts (r0-{args.size}, ...)")
    capacity = None if args.capacity == "inf" else int(args.capacity)
    engine = OrderEngine(plans[args.plan])
    value = None
    if args.bin == "pile":
        best, value, gap, rows = pile_differences(engine, args.visible, capacity)
    else:
        best, gap, rows = differences(engine, args.visible, capacity)
    print(f"{args.plan}, {args.visible} visible, buffer {args.capacity}: optimum {best:.4f}; the fallback acts "
          f"otherwise at {len(rows)} looks of its path; gap {gap:.4f} ({100 * gap / best:+.3f}%)")
    if value is not None:
        print(f"  the fallback's value summed along its path {value:.6f} ({100 * (value / best - 1):+.3f}%)")
    for words, by in (("units installed", lambda row: row["installed"]),
                      ("strategies open", lambda row: row["strategies"].bit_count())):
        print(f"  the gap by {words}: " + (", ".join(f"{k}: {100 * v / best:+.3f}%" for k, v in split(rows, by))
                                              or "none"))
    rows.sort(key=lambda row: -row["looks"] * row["advantage"])
    for row in rows[:args.top]:
        print(f"  {row['looks'] * row['advantage']:.4f} = {row['looks']:.4f} looks x {row['advantage']:.4f}: "
              f"{row['installed']} installed, buffer {list(row['buffer'])}, strategies {row['strategies']:b}, "
              f"look {list(row['look'])}{'' if row.get('fresh', True) else ' (after a move)'}: "
              f"optimum {row['optimum']}, fallback {row['fallback']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
