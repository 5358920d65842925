"""The rollout policy (policies/rollout.py): legal, reproducible, within its budget, exact where small."""

from __future__ import annotations

import math
import os
import random
import subprocess
import sys

from hypothesis import given, settings

from conftest import GEARBOX, CpuTime, random_plans
from opportune import Sequencer, load_plan
from opportune.datasets import salbp
from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.named import POLICIES, UnknownPolicy, make_policy
from opportune.policies.rollout import Rollout
from opportune.policies.lookahead import Lookahead


@settings(max_examples=15, deadline=None)
@given(plan=random_plans(max_parts=5, max_units=6, max_strategies=2))
def test_sampled_rollouts_are_legal_everywhere_and_never_beat_the_optimum(plan):
    """Evaluated exactly over every state it can reach (the evaluator refuses an illegal action), with
    an unlimited buffer and with one location."""
    engine = OrderEngine(plan)
    for capacity in (None, 1):
        policy = Rollout(samples=3, exact_below=0, capacity=capacity)   # sampled even on a small plan
        ev = PolicyEvaluator(engine, policy, visible=2, capacity=capacity)
        assert ev.value() >= ev.optimal() - 1e-9


def test_on_small_plans_it_is_the_exact_lookahead():
    engine = OrderEngine(load_plan(GEARBOX))
    plan = engine.plan
    rollout, ahead = Rollout(), Lookahead(visible=2)
    rng = random.Random(0)
    for _ in range(30):
        look = tuple(sorted(rng.sample(plan.part_ids, 2), key=plan.index))
        assert rollout.choose_at(engine, 0, 1, (), math.inf, look) == ahead.choose_at(engine, 0, 1, (), math.inf, look)


def test_the_same_state_gives_the_same_decision_in_any_process():
    """The futures' seed comes from the state, not from Python's per-process string hashing."""
    code = ("from opportune.datasets import salbp; from opportune.engine import OrderEngine;"
            "from opportune.policies.rollout import Rollout; import math, random;"
            "e = OrderEngine(salbp('TONGE70')); p = e.plan; r = random.Random(5); out = []\n"
            "for _ in range(8):\n"
            "    look = tuple(sorted(r.sample(p.part_ids, 3), key=p.index))\n"
            "    a = Rollout(samples=4, visible=3).choose_at(e, 0, 1, (), math.inf, look)\n"
            "    out.append((a.kind, a.part))\n"
            "print(out)")
    answers = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                              env={**os.environ, "PYTHONHASHSEED": seed}).stdout for seed in ("1", "2")}
    assert len(answers) == 1 and "buffer" in answers.pop()


def test_a_budget_is_kept_on_a_large_plan():
    plan = salbp("ARC111")
    engine = OrderEngine(plan)
    budget = 0.02
    policy = Rollout(budget=budget, min_samples=2)
    rng = random.Random(2)
    seq = Sequencer(engine, policy, budget=budget)
    slowest = 0.0
    for _ in range(40):
        if seq.state.is_complete:
            break
        in_bin = [p for p, n in seq.state.in_bin.items() for _ in range(n)]
        look = tuple(rng.sample(in_bin, min(2, len(in_bin))))
        with CpuTime() as cpu:
            decision = seq.decide(look)
        slowest = max(slowest, cpu.seconds)
        assert decision.explain()
        seq.report("success")
    # 80% of the budget for the futures, then at most one round more and the bookkeeping
    assert slowest < 5 * budget, slowest


def test_the_policies_by_name():
    for name in POLICIES:
        policy = make_policy(name, budget=0.05)
        assert callable(getattr(policy, "decide"))
    try:
        make_policy("teleport")
    except UnknownPolicy as exc:
        assert "teleport" in str(exc) and "lookahead" in str(exc)
    else:
        raise AssertionError("an unknown policy was made")
