"""A long-running cell: one order engine reused for assembly after assembly.

Its memos and per-state caches reach their caps again and again.  Dropping entries inside a
decision took a reused engine's decisions past their budget (207 ms against 50 on ARC111), so the
engine holds that work back while a decision runs and does it between looks
(``OrderEngine.deciding`` / ``OrderEngine.maintain``, called by the sequencer after each outcome).
These tests count the work: no eviction, restart or cache clearing happens inside a decision, it
does happen between them, and the decisions are those of a fresh engine.
"""

from __future__ import annotations

import random

import pytest

from opportune.engine import OrderEngine
from opportune.engine import count as count_module
from opportune.engine import tuning
from opportune.engine.native import NativeCounter
from opportune.policies.opportunistic import Opportunistic
from opportune.sequencer import Sequencer

CACHES = ("_count_cache", "_option_cache", "_options_cache", "_positions_cache", "_installable_cache")


def two_strategy_plan(n: int = 14, seed: int = 5):
    """Two random partial orders on ``n`` parts (two strategies: the engine's per-state count cache
    is used, not only the counters' memos)."""
    rng = random.Random(seed)
    ids = [f"p{i}" for i in range(n)]
    strategies = []
    for s in range(2):
        order = rng.sample(range(n), n)
        requires: dict[str, list[str]] = {}
        for j in range(n):
            for i in range(j):
                if rng.random() < 0.12:
                    requires.setdefault(ids[order[j]], []).append(ids[order[i]])
        strategies.append({"name": f"s{s}", "requires": requires})
    from opportune.formats import plan_from_dict

    return plan_from_dict({"name": "two", "parts": ids, "strategies": strategies})


def assemblies(engine_of, plan, n: int, seed: int, budget=None, on_decision=None):
    """``n`` assemblies (uniform bin, two parts per look, every action succeeding); their actions."""
    rng = random.Random(seed)
    actions = []
    for _ in range(n):
        engine = engine_of()
        seq = Sequencer(engine, Opportunistic(budget=budget, seed=1), budget=budget)
        while not seq.state.is_complete:
            in_bin = [p for p, k in seq.state.in_bin.items() for _ in range(k)]
            look = tuple(rng.sample(in_bin, min(2, len(in_bin))))
            before = {c: len(getattr(engine, c)) for c in CACHES}
            decision = seq.decide(look)
            if on_decision:
                on_decision(engine, before)
            actions.append(decision.action)
            seq.report("success")
    return actions


@pytest.mark.parametrize("budget", [None, 0.05])
def test_memo_upkeep_happens_between_decisions_never_inside_one(monkeypatch, budget):
    plan = two_strategy_plan()
    monkeypatch.setattr(tuning, "STATE_CACHE_LIMIT", 40)     # small caps: reached every assembly
    shared = OrderEngine(plan)
    for strategies in (1, 2, 3):
        shared.counter(strategies).max_total = 60

    during, between = [], []

    def noting(real, what):
        def wrapper(self, *args, **kw):
            (during if shared._deciding else between).append(what)
            return real(self, *args, **kw)
        return wrapper

    monkeypatch.setattr(count_module.Counter, "_evict", noting(count_module.Counter._evict, "evict"))
    monkeypatch.setattr(NativeCounter, "reset", noting(NativeCounter.reset, "restart"))

    shrunk = []

    def check(engine, before):
        # a per-state cache cleared inside the decision would be smaller after it than before
        shrunk.extend(c for c in CACHES if len(getattr(engine, c)) < before[c])

    reused = assemblies(lambda: shared, plan, 12, seed=3, budget=budget, on_decision=check)
    assert not during, during                   # nothing dropped while a decision ran ...
    assert not shrunk, shrunk
    assert between and shared.maintained > 0   # ... but it was, between decisions
    assert all(len(getattr(shared, c)) <= 40 for c in CACHES)   # after the last outcome: within the caps
    for c in filter(None, shared._counters.values()):              # each memo within its cap
        assert len(c._memo) + len(c._vec) <= 60 and (c._native is None or c._native.size() <= 60)
    if budget is None:      # exact decisions: the same as a fresh engine's, assembly by assembly
        assert reused == assemblies(lambda: OrderEngine(plan), plan, 12, seed=3)


def test_maintenance_waits_for_every_overlapping_decision():
    """Threads sharing one engine: upkeep waits until no decision is under way."""
    engine = OrderEngine(two_strategy_plan())
    counter = engine.counter(engine.all_strategies)
    counter.max_total = 1
    with engine.deciding():
        engine.count(0, engine.all_strategies)
        with engine.deciding():
            assert counter.hold_upkeep
        assert counter.hold_upkeep and engine.maintain() is False     # the outer decision is still running
        engine.count(0, 1)                                              # a new call: no eviction either
        assert engine.counter(1).hold_upkeep                            # (a counter made inside one too)
    assert not counter.hold_upkeep
    assert engine.maintain() is True and engine.maintained == 1
    assert engine.maintain() is False                                   # nothing left to do
