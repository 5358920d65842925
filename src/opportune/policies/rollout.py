"""Rollout: score each action by the mean cost of finishing over sampled futures (issue 13).

The exact look-ahead (:class:`~opportune.policies.lookahead.Lookahead`) evaluates its base policy by a
dynamic programme, which only small plans allow.  On a large plan, :class:`Rollout` estimates the
same quantity by sampling: for each legal action, the cost of the action plus the cost of finishing
the assembly from where it leads with a cheap base rule, in a simulated uniform bin, averaged over
sampled futures.  Every action is scored on the *same* futures (common random numbers: round ``r``
seeds every action's future alike), so the comparison is paired and its noise much smaller than
the spread of the costs.  The least mean wins; a tie keeps the base rule's own action.

The base rule of the futures counts nothing, so that a future of a 100-part plan costs about a
millisecond:

* install a visible part before a buffered one (the buffer keeps); among them the part with the
  most steps waiting on it;
* when nothing can be installed, buffer the visible part with the fewest predecessors still
  missing (ties: the most steps waiting on it); shake when the buffer is full.

Budget.  Without one, every decision samples ``samples`` futures per action (the same decision
for the same state and seed, on any machine).  With ``budget`` seconds, rounds of futures run until
80% of it is spent, a round cut there dropped (a future reads the clock every 16 steps, every step on a
plan written as ways); with fewer
than ``min_samples`` rounds the decision is the base rule's, said so in its reasons.  The number of
rounds, and so the decision, then depends on the machine's speed.

Plans of at most :attr:`Rollout.EXACT_UNITS` units are decided by the exact look-ahead instead:
there the expectation is computed, not sampled.
"""

from __future__ import annotations

import math
import random
import time
import zlib

from opportune.engine.deadline import BudgetExceeded

from opportune.engine.tuning import ROLLOUT_EXACT_UNITS, ROLLOUT_SHARE
from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Decision, shared_action
from opportune.policies.look import LookState

__all__ = ["Rollout"]


class Rollout(DecidesOnMasks):
    """One step of policy improvement over a cheap base rule, by sampled futures with common random numbers.

    >>> from opportune import make_plan, Sequencer
    >>> plan = make_plan(["a", "b", "c"], {"c": ["a"]})
    >>> Rollout(samples=8, exact_below=0).choose_at(Sequencer(plan).state.schedule.engine, 0, 1, (), 1.0, ("c", "b"))
    Action(kind='install', part='b', source='bin')
    """

    name = "rollout"
    rule = "the action with the least mean cost of finishing, over sampled futures (common random numbers)"
    decision_key = None
    #: Plans of at most this many units are decided by the exact look-ahead (an expectation, not a sample):
    #: its programme (the optimum's where it fits) finishes within seconds on them.
    EXACT_UNITS = ROLLOUT_EXACT_UNITS
    #: The futures' seed is drawn from the state with its buffer in order (and small plans decide as the
    #: look-ahead, which keeps it too).
    uses_buffer_order = True

    def buffer_ties_at(self, engine, mask: int, consistent: int):
        """Where the order of the buffer can decide (see :meth:`Opportunistic.buffer_ties_at
        <opportune.policies.opportunistic.Opportunistic.buffer_ties_at>`): the look-ahead's on a small plan;
        None (any pair) on a larger one, whose futures are drawn from the whole buffer's order."""
        if self._exact_for(engine):
            return self._exact_policy().buffer_ties_at(engine, mask, consistent)
        return None

    def __init__(self, *, samples: int = 16, budget: float | None = None, min_samples: int = 4, seed: int = 0,
                 visible: int = 2, capacity: int | None = None, costs=None, exact_below: int | None = None,
                 exact=None):
        from opportune.planning.costs import TimeModel

        self.samples = samples
        self.budget = budget
        self.min_samples = min_samples
        self.seed = seed
        self.visible = visible
        self.capacity = capacity
        self.costs = costs if costs is not None else TimeModel()
        self.deterministic = budget is None
        # small plans: the exact look-ahead (an expectation, not a sample)
        self.exact_below = self.EXACT_UNITS if exact_below is None else exact_below
        self.exact = exact
        self._tables = None
        self._stop = math.inf       # the moment the futures of a decision stop (the budget's share)
        self.last: dict | None = None

    # ------------------------------------------------------------------ tables of the plan

    def _prepare(self, engine) -> tuple:
        if self._tables is None or self._tables[0] is not engine:
            plan = engine.plan
            n = len(plan.parts)
            first = [engine.next_unit(0, p) for p in range(n)]
            unit_part = [0] * engine.n_units
            for p, part in enumerate(plan.parts):
                for u in range(first[p], first[p] + part.quantity):
                    unit_part[u] = p
            # steps waiting on a unit, in the strategy that has the most (a static priority)
            waiting = [engine.steps_waiting(u) for u in range(engine.n_units)]
            move = [self.costs.move(part.id) for part in plan.parts]
            self._quantity = [part.quantity for part in plan.parts]
            self._tables = (engine, first, unit_part, waiting, move, {part.id: p for p, part in enumerate(plan.parts)})
        return self._tables

    # ------------------------------------------------------------------ the decision

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        if mask == engine.full:
            return DONE
        self.last = None
        look = LookState(engine, mask, consistent, buffer, free, visible)
        if self._exact_for(engine):
            return self._exact_policy().choose_look(look)
        actions = self._actions(look)
        base = actions[0]
        if len(actions) == 1:
            return base
        deadline = None if self.budget is None else time.perf_counter() + ROLLOUT_SHARE * self.budget
        tables = self._prepare(engine)
        index = tables[5]
        bin_parts = self._bin_parts(engine, mask, buffer, tables)
        totals = [0.0] * len(actions)
        # the futures' seed: the same state and look give the same futures, in any process
        stream = zlib.crc32(repr((self.seed, mask, consistent, buffer, tuple(sorted(visible)))).encode())
        rounds = 0
        self._stop = math.inf if deadline is None else deadline
        while rounds < self.samples if deadline is None else time.perf_counter() < deadline:
            seed = (stream << 20) | rounds
            try:    # a round cut at the deadline is dropped (every action's future, or none)
                costs = [self._cost_after(engine, tables, mask, consistent, buffer, bin_parts, action, index,
                                          random.Random(seed)) for action in actions]
            except BudgetExceeded:
                break
            totals = [t + c for t, c in zip(totals, costs)]
            rounds += 1
        if rounds < self.min_samples:
            self.last = {"rounds": rounds, "fallback": True}
            return base
        means = [t / rounds for t in totals]
        best = min(range(len(actions)), key=lambda i: (means[i], i))    # ties: the earlier (the base's first)
        self.last = {"rounds": rounds, "means": {_label(a): m for a, m in zip(actions, means)}, "fallback": False}
        return actions[best]

    def _exact_for(self, engine) -> bool:
        """Whether the exact look-ahead decides on this engine's plan (one of at most :attr:`exact_below`
        units, written either way); else the futures are sampled."""
        return engine.n_units <= self.exact_below

    def _exact_policy(self):
        if self.exact is None:
            from opportune.policies.lookahead import Lookahead

            self.exact = Lookahead(budget=self.budget, visible=self.visible, capacity=self.capacity,
                                   costs=self.costs)
        return self.exact

    def _actions(self, look: LookState) -> list[Action]:
        """The candidate actions, the base rule's first: installs if any (bin before buffer), else
        buffering each distinct visible part (with room) and shaking."""
        engine, mask, consistent, buffer, free, visible = look
        tables = self._prepare(engine)
        _, first, _, waiting, _, index = tables

        def waiting_of(part):
            return waiting[engine.next_unit(mask, index[part])]

        in_bin = engine.installable_among(mask, consistent, set(visible))
        in_buffer = engine.installable_among(mask, consistent, set(buffer)) if buffer else []
        if in_bin or in_buffer:
            def rank(p):
                return -waiting_of(p), index[p]

            out = [shared_action("install", p, "bin") for p in sorted(in_bin, key=rank)]
            return out + [shared_action("install", p, "buffer") for p in sorted(in_buffer, key=rank)]
        if free <= 0 or not visible:
            return [SHAKE]
        def missing(part):
            return engine.waits(mask, engine.all_strategies, engine.next_unit(mask, index[part]))[0]

        parts = sorted(set(visible), key=lambda p: (missing(p), -waiting_of(p), index[p]))
        # no shake while the buffer has room: a motion into the buffer keeps the part, a shake keeps nothing
        return [shared_action("buffer", p) for p in parts]

    @staticmethod
    def _bin_parts(engine, mask, buffer, tables) -> list[int]:
        """The units in the bin (not installed, not buffered), as part indices."""
        _, _, unit_part, _, _, index = tables
        out = [unit_part[u] for u in range(engine.n_units) if not mask >> u & 1]
        for part in buffer:
            out.remove(index[part])
        return out

    def _cost_after(self, engine, tables, mask, consistent, buffer, bin_parts, action, index, rng) -> float:
        """Cost of ``action`` plus a sampled future's cost of finishing by the base rule."""
        _, first, unit_part, waiting, move, _ = tables
        costs = self.costs
        bin_parts = list(bin_parts)
        buffer = [index[p] for p in buffer]
        p = index.get(action.part) if action.part is not None else None
        if action.kind == "install":
            if action.source == "buffer":
                buffer.remove(p)
            else:
                bin_parts.remove(p)
            u = engine.next_unit(mask, p)
            consistent = engine.consistent_after(mask, consistent, u)
            mask |= 1 << u
            t = move[p]
        elif action.kind == "buffer":
            bin_parts.remove(p)
            buffer.append(p)
            t = move[p]
        else:
            t = costs.shake
        return t + self._finish(engine, tables, mask, consistent, buffer, bin_parts, rng)

    def _finish(self, engine, tables, mask, consistent, buffer, bin_parts, rng) -> float:
        """A sampled future: the base rule in a uniform bin until the assembly is complete."""
        _, first, unit_part, waiting, move, _ = tables
        posets = engine.posets
        single = len(posets) == 1
        # the first strategy's order (a plan written as ways has none: the engine says what is missing)
        below = posets[0].below if posets else None
        full = engine.full
        k = self.visible
        cap = self.capacity
        look_cost, shake_cost = self.costs.look, self.costs.shake
        quantity = self._quantity
        rand = rng.random
        t = 0.0
        steps = 0
        limit = 20 * engine.n_units + 100

        def next_unit(p):
            u = first[p]
            if quantity[p] > 1:
                while mask >> u & 1:
                    u += 1
            return u

        def ok(u):
            if single:
                return below[u] & ~mask == 0
            return engine.consistent_after(mask, consistent, u) != 0

        stop = self._stop
        # the clock read every 16 steps, every step on a plan written as ways (a step's liveness test
        # there is O(ways), not O(1))
        every = 15 if posets else 0
        while mask != full and steps < limit:
            steps += 1
            if not steps & every and stop < math.inf and time.perf_counter() >= stop:
                raise BudgetExceeded("a sampled future past the decision's deadline")
            t += look_cost
            n = len(bin_parts)
            if n <= k:
                seen = list(range(n))
            elif k == 2:
                i = int(rand() * n)
                j = int(rand() * (n - 1))
                seen = [i, j + (j >= i)]
            else:
                seen = rng.sample(range(n), k)
            # install: a visible part first, the one with the most waiting on it
            best = None
            for i in seen:
                u = next_unit(bin_parts[i])
                if ok(u) and (best is None or waiting[u] > best[0]):
                    best = (waiting[u], i, u)
            if best is not None:
                _, i, u = best
                p = bin_parts[i]
                bin_parts[i] = bin_parts[-1]
                bin_parts.pop()
            else:
                for j, p in enumerate(buffer):
                    u = next_unit(p)
                    if ok(u) and (best is None or waiting[u] > best[0]):
                        best = (waiting[u], j, u)
                if best is not None:
                    _, j, u = best
                    p = buffer.pop(j)
            if best is not None:
                if not single:
                    consistent = engine.consistent_after(mask, consistent, u)
                mask |= 1 << u
                t += move[p]
                continue
            if n == 0:
                break           # nothing in the bin and nothing installable: a broken plan; stop
            if cap is not None and len(buffer) >= cap:
                t += shake_cost
                continue
            remaining = full & ~mask
            pick = None
            for i in seen:
                u = next_unit(bin_parts[i])
                missing = (below[u] & remaining).bit_count() if below is not None else engine.waits(mask, 1, u)[0]
                key = (missing, -waiting[u])
                if pick is None or key < pick[0]:
                    pick = (key, i)
            i = pick[1]
            p = bin_parts[i]
            bin_parts[i] = bin_parts[-1]
            bin_parts.pop()
            buffer.append(p)
            t += move[p]
        return t

    def decide(self, state, visible: tuple[str, ...]) -> Decision:
        if self._exact_for(state.schedule.engine):
            return self._exact_policy().decide(state, visible)
        action = self.choose(state, visible)
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        last = self.last
        if last is None:
            return Decision(action, "the only candidate action")
        if last["fallback"]:
            return Decision(action, f"the base rule's action: only {last['rounds']} sampled futures fitted the "
                                    "decision budget", exact=False, method="rollout")
        means = ", ".join(f"{a} {m:.2f}" for a, m in sorted(last["means"].items(), key=lambda kv: kv[1]))
        return Decision(action, self.rule, note=f"mean cost of finishing over {last['rounds']} futures: {means}",
                        exact=False, method="rollout")


def _label(action: Action) -> str:
    if action.kind == "install":
        return f"install {action.part} ({action.source})"
    return action.kind if action.part is None else f"{action.kind} {action.part}"
