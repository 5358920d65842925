"""Where the fallback loses to the optimum: the looks on its own path at which the default policy without
its optimum (``Lookahead(optimal=False)``: the frontier window) acts otherwise than the optimum, each with
how often its run meets that look and what its action costs there (the optimum's expected cost after the
fallback's action, less after the optimum's: its *advantage*).  The terms sum to the fallback's gap
exactly; the largest say which decisions to look at.

The uniform bin; states as the optimum keeps them (the buffer as counts per part: the fallback is asked
with the buffer in declaration order).  A lab plan by its name (``--size``, ``--plan``, the lab's seed-0
plans), the setting by ``--visible`` and ``--capacity``::

    python benchmarks/fallback_diagnosis.py --size 16 --plan r20-16x2 --visible 1 --capacity 1
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, required=True, help="the lab's plans of this many parts")
    ap.add_argument("--plan", required=True, help="the plan's name in the lab (r20-16x2, ...)")
    ap.add_argument("--visible", type=int, default=1)
    ap.add_argument("--capacity", default="1", help="buffer locations (inf: unlimited)")
    ap.add_argument("--top", type=int, default=8, help="the largest terms shown")
    args = ap.parse_args(argv)
    plans = {plan.name: plan for plan, _ in generate(0, 30, args.size, args.size)}
    if args.plan not in plans:
        ap.error(f"--plan: none named {args.plan!r} of {args.size} parts (r0-{args.size}, ...)")
    capacity = None if args.capacity == "inf" else int(args.capacity)
    engine = OrderEngine(plans[args.plan])
    best, gap, rows = differences(engine, args.visible, capacity)
    print(f"{args.plan}, {args.visible} visible, buffer {args.capacity}: optimum {best:.4f}; the fallback acts "
          f"otherwise at {len(rows)} looks of its path; gap {gap:.4f} ({100 * gap / best:+.3f}%)")
    rows.sort(key=lambda row: -row["looks"] * row["advantage"])
    for row in rows[:args.top]:
        print(f"  {row['looks'] * row['advantage']:.4f} = {row['looks']:.4f} looks x {row['advantage']:.4f}: "
              f"{row['installed']} installed, buffer {list(row['buffer'])}, strategies {row['strategies']:b}, "
              f"look {list(row['look'])}: optimum {row['optimum']}, fallback {row['fallback']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
