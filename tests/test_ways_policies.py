"""The count-based policies on plans written as ways: the same decisions as on the strategy a one-strategy
plan of ways was written from, only admitted sequences on random plans of ways in every bin, and the
decision budget kept however slow the engine's answers are (an injected clock)."""

from __future__ import annotations

import itertools
import random
import time
from pathlib import Path

import pytest
from hypothesis import assume, given, settings, strategies as st

from opportune.engine import OrderEngine, Schedule
from opportune.engine.ways import WaysCounter
from opportune.formats.loader import make_plan
from opportune.formats.ways import WAYS_POLICIES, ways_of_strategy
from opportune.planning.ways import WaysTable
from opportune.policies.named import make_policy
from opportune.policies.rollout import Rollout
from test_ways import admitted, random_ways_plan


def one_strategy(rng: random.Random, n: int):
    ids = [f"p{i}" for i in range(n)]
    return make_plan(ids, {ids[j]: [ids[i] for i in range(j) if rng.random() < 0.35] for j in range(n)})


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 7), st.integers(0, 10**9))
def test_the_ways_answer_what_waits_as_the_strategy_does(n, seed):
    """The installs still needed before a part and the steps that wait on it, read from the ways of a
    strategy written as ways, are the partial order's, in every state."""
    plan = one_strategy(random.Random(seed), n)
    order, ways = OrderEngine(plan), OrderEngine(ways_of_strategy(plan))
    for mask in range(1 << n):
        below = order.posets[0].below
        if any(below[u] & ~mask for u in range(n) if mask >> u & 1):     # not a state: not a down-set
            continue
        for u in range(n):
            if not mask >> u & 1:
                assert ways.waits(mask, 1, u) == order.waits(mask, 1, u), (mask, u)
        s_order, s_ways = Schedule.at(order, mask, 1, ()), Schedule.at(ways, mask, 1, ())
        for p in plan.part_ids:
            assert s_ways.missing_before(p) == s_order.missing_before(p)
    assert [ways.steps_waiting(u) for u in range(n)] == [order.steps_waiting(u) for u in range(n)]


def _looks(rng: random.Random, plan, engine, states: int):
    """Random states reached by installing, each with a random buffer and look."""
    ids = plan.part_ids
    for _ in range(states):
        s = Schedule(engine)
        for _ in range(rng.randrange(len(ids))):
            can = s.installable()
            if not can:
                break
            s = s.install(rng.choice(can))
        left = [p for p in ids if not s.mask >> plan.index(p) & 1]
        if not left:
            continue
        buffer = tuple(rng.sample(left, rng.randint(0, min(2, len(left) - 1))))
        rest = [p for p in left if p not in buffer]
        visible = tuple(sorted(rng.sample(rest, min(len(rest), rng.randint(1, 3))), key=plan.index))
        yield s.mask, buffer, visible


@pytest.mark.parametrize("policy", ["slack", "rollout"])
@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 8), seed=st.integers(0, 10**9))
def test_a_strategy_written_as_ways_is_decided_as_the_strategy(policy, n, seed):
    rng = random.Random(seed)
    plan = one_strategy(rng, n)
    order, ways = OrderEngine(plan), OrderEngine(ways_of_strategy(plan))
    for mask, buffer, visible in _looks(rng, plan, order, 6):
        free = rng.choice([0, 1, float("inf")]) if buffer else rng.choice([1, float("inf")])
        # the rollout samples its futures (exact_below=0): the same futures on both engines
        decide = [(make_policy(policy) if policy == "slack" else Rollout(samples=6, exact_below=0))
                  .choose_at(e, mask, 1, buffer, free, visible) for e in (order, ways)]
        assert decide[0] == decide[1], (mask, buffer, visible)


def _run(plan, engine, policy, bin_name: str, seed: int) -> list[str]:
    """One trial in a simulated bin, every install checked against the plan's definition."""
    from opportune.worlds import make_world

    weights = {p: 1.0 + i for i, p in enumerate(plan.part_ids)} if bin_name == "weighted" else None
    world = make_world(bin_name, visible=2, weights=weights)
    world.reset(list(plan.part_ids), random.Random(seed))
    mask, buffer, installed, cap = 0, (), [], 2
    for _ in range(40 * len(plan.parts)):
        if mask == engine.full:
            break
        look = tuple(sorted(world.look(), key=plan.index))
        action = policy.choose_at(engine, mask, 1, buffer, cap - len(buffer), look)
        if action.kind == "install":
            if action.source == "buffer":
                buffer = tuple(p for p in buffer if p != action.part)
            else:
                world.take(action.part)
            installed.append(action.part)
            assert admitted(plan, installed), installed
            mask |= 1 << plan.index(action.part)
        elif action.kind == "buffer":
            world.take(action.part)
            buffer += (action.part,)
        else:
            assert action.kind == "shake", action
            world.shake()
    return installed


@pytest.mark.parametrize("bin_name", ["uniform", "weighted", "pile"])
@pytest.mark.parametrize("policy", ["slack", "rollout"])
@settings(max_examples=6, deadline=None)
@given(n=st.integers(3, 9), seed=st.integers(0, 10**9), needs=st.booleans())
def test_every_trial_on_a_random_plan_of_ways_completes_with_an_admitted_sequence(policy, bin_name, n, seed, needs):
    rng = random.Random(seed)
    plan = random_ways_plan(rng, n, needs=needs)
    assume(WaysCounter(WaysTable.of(plan)).count(0))       # a plan with an admissible sequence
    engine = OrderEngine(plan)
    chosen = make_policy(policy, budget=None) if policy == "slack" else Rollout(samples=4, exact_below=0)
    installed = _run(plan, engine, chosen, bin_name, seed)
    assert sorted(installed) == sorted(plan.part_ids) and admitted(plan, installed)


@pytest.mark.parametrize("policy", ["slack", "rollout"])
def test_replay_takes_slack_and_rollout_on_a_ways_file(tmp_path, policy):
    from typer.testing import CliRunner

    from opportune.cli import app
    from test_ways import WAYS_YAML

    assert policy in WAYS_POLICIES
    path, looks = tmp_path / "peg.yaml", tmp_path / "looks.txt"
    path.write_text(WAYS_YAML)
    looks.write_text("peg cap\nbase\ncap\n-\n")
    replayed = CliRunner().invoke(app, ["replay", "--policy", policy, str(path), str(looks)])
    assert replayed.exit_code == 0 and "complete: base,cap,peg" in replayed.output, replayed.output


def test_the_ways_bound_what_waits_where_the_order_cannot():
    """Two ways in (peg from above after the base, or from the side after the cap): nothing waits on the
    base alone, one install is missing before the peg either way, and the peg waits on base or cap."""
    from opportune.formats.ways import ways_plan
    from opportune.planning.plan import Part, Way

    plan = ways_plan("peg", [Part("base"), Part("cap"), Part("peg")],
                     {"peg": [Way(frozenset(), (frozenset({"base"}),)), Way(frozenset(), (frozenset({"cap"}),))]})
    engine = OrderEngine(plan)
    assert engine.waits(0, 1, 2) == (1, 0)      # base or cap first: one install
    assert engine.waits(0, 1, 0) == (0, 0)      # the peg may go in after the cap instead
    brute = [s for s in itertools.permutations(plan.part_ids) if admitted(plan, s)]
    assert all(s.index("peg") > min(s.index("base"), s.index("cap")) for s in brute)


BLOCK30 = Path(__file__).parent / "data" / "ways-block30.yaml"     # `opportune derive` of a random voxel block


class SlowClock:
    """A clock that moves only with the work of the engine of ways: each call of a unit of it (a set's
    parts that can go in, a liveness test, a walk's step) costs ``cost`` seconds, as on a machine that
    slow; ``time.perf_counter`` reads it."""

    def __init__(self, monkeypatch, cost: float):
        from opportune.engine import deadline, ways as engine_ways
        from opportune.planning.ways import WaysTable as Table

        self.now, self.cost = 1000.0, cost
        monkeypatch.setattr(time, "perf_counter", self.read)
        monkeypatch.setattr(deadline, "_perf", self.read)
        # the units of O(ways) or more (a part going in, O(the ways naming it), is not one)
        for owner, name in ((Table, "goes"), (Table, "shutting"), (Table, "locked"), (Table, "before"),
                            (Table, "_open_ways_of"), (engine_ways._Walk, "choices"), (engine_ways._Walk, "locked")):
            monkeypatch.setattr(owner, name, self.charged(getattr(owner, name)))

    def read(self) -> float:
        """The time, a tenth of a unit later (a reading costs too: work found in a cache still moves it)."""
        self.now += self.cost / 10
        return self.now

    def charged(self, work):
        def slow(*args, **kwargs):
            self.now += self.cost
            return work(*args, **kwargs)
        return slow


@pytest.mark.parametrize("policy", ["paper", "bin-first", "slack", "rollout"])
def test_a_decision_on_a_plan_of_ways_keeps_its_budget_however_slow_the_work(monkeypatch, policy):
    """On a derived block of 30 parts, with every unit of the ways' work costing a millisecond of an
    injected clock, each decision ends within its budget and one unit of work between two readings of
    the clock: the exact count's (4 sets), a walk's step, a liveness test (at most 10 units)."""
    from opportune import load_plan
    from opportune.sequencer import Sequencer

    plan = load_plan(BLOCK30)
    budget, cost = 0.05, 0.001
    chosen = make_policy(policy, budget=budget) if policy != "rollout" else Rollout(budget=budget, exact_below=0)
    seq = Sequencer(plan, chosen, buffer_capacity=2, budget=budget, warm_up=0.01)
    clock = SlowClock(monkeypatch, cost)
    rng = random.Random(3)
    slowest, estimated = 0.0, 0
    for _ in range(25):
        if seq.state.is_complete:
            break
        in_bin = [p for p, n in seq.state.in_bin.items() for _ in range(n)]
        start = clock.now
        decision = seq.decide(tuple(rng.sample(in_bin, min(2, len(in_bin)))))
        slowest = max(slowest, clock.now - start)
        estimated += not decision.exact
        seq.report("success")
    assert slowest <= budget + 10 * cost, slowest
    assert estimated, "every decision was exact: the clock was not slow enough to test the budget"
