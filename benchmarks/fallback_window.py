"""A candidate fallback for the default policy, measured, not part of the package: the exact optimum of a
frontier window.

Where the look-ahead's exact optimum does not fit it decides as ``slack`` past 16 units (+3% to +19% above
the optimum on 18-30-part plans with few buffer locations).  The candidate: at each state, the window is
the buffered parts and the ``m`` remaining parts first in a topological order (fewest remaining ancestors
first, then declaration order), closed under remaining ancestors; the other remaining parts are
aggregated into one part ``_rest`` of as many units, required after the whole window (in the bin they
dilute the looks as they do on the real plan).  The reduced plan's exact optimum
(:func:`~opportune.policies.optimal.optimal_solver`: compiled up to 64 units, else the Python
programme) is solved once per state (cached), and the decision is its best action on the look, a
visible part outside the window seen as ``_rest``.  Plans of one strategy and parts of one unit only.

    python benchmarks/fallback_window.py --m 12 --sizes 16,20,25,30 --settings 1x1,2x2   # gap to the optimum
    python benchmarks/fallback_window.py --m 8 --decisions salbp:ARC111 --settings 1x1,2x2,3x2   # CPU per decision
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
from pathlib import Path

from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.policies.base import DONE, SHAKE, Action
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.optimal import optimal_solver

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_fallback import draw_plans  # noqa: E402


class FrontierWindow:
    """The exact optimum of the window of the next ``m`` parts, the rest aggregated (see the module)."""

    name = "window"
    deterministic = True
    decision_key = None

    def __init__(self, m: int, visible: int, capacity: int | None):
        self.m, self.visible, self.capacity = m, visible, capacity
        self._engine = None
        self.solves, self.solve_seconds = 0, 0.0

    def _tables(self, engine) -> None:
        if self._engine is engine:
            return
        plan = engine.plan
        if len(plan.strategies) != 1 or any(p.quantity != 1 for p in plan.parts):
            raise ValueError("the window candidate takes plans of one strategy and parts of one unit")
        self._engine, self.ids, self._cache = engine, plan.part_ids, {}
        self.preds = {p: set() for p in self.ids}
        for a, b in plan.strategies[0].pairs():
            self.preds[b].add(a)
        self.anc: dict[str, set] = {}
        for p in self.ids:                      # declaration order need not be topological: by depth-first
            stack = [p]
            while stack:
                q = stack[-1]
                todo = [a for a in self.preds[q] if a not in self.anc]
                if todo:
                    stack.extend(todo)
                    continue
                stack.pop()
                self.anc[q] = set().union(*({a} | self.anc[a] for a in self.preds[q])) if self.preds[q] else set()

    def _reduced(self, engine, mask: int, buffer: tuple[str, ...]):
        remaining = [p for i, p in enumerate(self.ids) if engine.next_unit(mask, i) is not None]
        left = set(remaining)
        order = sorted(remaining, key=lambda p: (len(self.anc[p] & left), engine.plan.index(p)))
        window: set[str] = set()
        for p in list(buffer) + order:
            if len(window) >= self.m and p not in buffer:
                break
            window |= {p} | (self.anc[p] & left)
        parts = [p for p in remaining if p in window]
        requires = {b: [a for a in self.preds[b] if a in window] for b in parts}
        if len(parts) < len(remaining):
            requires["_rest"] = list(parts)
            parts.append({"id": "_rest", "quantity": len(remaining) - len(parts)})
        start = time.process_time()
        solver = optimal_solver(OrderEngine(make_plan(parts, {k: v for k, v in requires.items() if v}, name="window")),
                                visible=self.visible, capacity=self.capacity, max_states=5_000_000)
        key = (0, solver.engine.all_strategies, solver.buffer_counts(buffer))
        solver.value(key)
        self.solves += 1
        self.solve_seconds += time.process_time() - start
        return solver, window, key

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        if mask == engine.full:
            return DONE
        self._tables(engine)
        state = (mask, tuple(sorted(buffer)))
        if state not in self._cache:
            self._cache[state] = self._reduced(engine, mask, buffer)
        solver, window, key = self._cache[state]
        look = tuple(sorted(solver.plan.index(p if p in window else "_rest") for p in visible))
        action, _ = solver.best_action(key, look)
        if action.kind == "shake" or action.part != "_rest":
            return action
        outside = [p for p in visible if p not in window]
        return Action("buffer", outside[0]) if action.kind == "buffer" else SHAKE


def gaps(args, settings) -> None:
    for n in map(int, args.sizes.split(",")):
        for plan in draw_plans(n, args.plans, args.seed, args.max_optimum_states, settings):
            for v, c in settings:
                policy, start = FrontierWindow(args.m, v, c), time.process_time()
                ev = PolicyEvaluator(OrderEngine(plan), policy, visible=v, capacity=c, max_states=1_000_000)
                gap = ev.value() / ev.optimal() - 1
                print(f"{n} parts, {plan.name}, {v} visible, {c} locations: window {args.m} {100 * gap:+.3f}% "
                      f"({ev.policy_states:,} states, {1000 * policy.solve_seconds / max(1, policy.solves):.1f} ms "
                      f"CPU a reduced optimum, {time.process_time() - start:.1f} s CPU)", flush=True)


def decisions(args, settings) -> None:
    """CPU time of each decision along one random run of the plan (a fresh state at every move)."""
    plan = load_plan(args.decisions)
    for v, c in settings:
        engine, rng = OrderEngine(plan), random.Random(args.seed)
        policy = FrontierWindow(args.m, v, c)
        mask, consistent, buffer, times = 0, engine.all_strategies, (), []
        while mask != engine.full:
            in_bin = [p for i, p in enumerate(plan.part_ids) if engine.next_unit(mask, i) is not None and p not in buffer]
            look = tuple(rng.sample(in_bin, min(v, len(in_bin))))
            start = time.process_time()
            action = policy.choose_at(engine, mask, consistent, buffer, c - len(buffer), look)
            times.append(time.process_time() - start)
            if action.kind == "buffer":
                buffer += (action.part,)
            elif action.kind == "install":
                unit = engine.next_unit(mask, plan.index(action.part))
                mask, consistent = mask | (1 << unit), engine.consistent_after(mask, consistent, unit)
                buffer = tuple(p for p in buffer if p != action.part)
        later = sorted(times[1:])       # the first decision also builds the plan's tables
        print(f"{plan.name}, {v} visible, {c} locations, window {args.m}: {len(times)} decisions, CPU ms: the first "
              f"{1000 * times[0]:.1f}, the others mean {1000 * statistics.mean(later):.1f}, 99th percentile "
              f"{1000 * later[int(0.99 * len(later))]:.1f}, max {1000 * later[-1]:.1f}; {policy.solves} reduced optima",
              flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--m", type=int, default=12, help="parts in the window (besides the buffered ones)")
    ap.add_argument("--sizes", default="16,20,25,30")
    ap.add_argument("--plans", type=int, default=3)
    ap.add_argument("--settings", default="1x1,2x2", help="VISIBLExLOCATIONS, comma-separated")
    ap.add_argument("--max-optimum-states", type=int, default=30_000)
    ap.add_argument("--decisions", help="time the decisions along a run of this plan instead (e.g. salbp:ARC111)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    settings = [tuple(map(int, s.split("x"))) for s in args.settings.split(",")]
    (decisions if args.decisions else gaps)(args, settings)
    return 0


if __name__ == "__main__":
    sys.exit(main())
