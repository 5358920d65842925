"""Counting through a hub with persistent memos: successive states of a simulation, position sums."""

from __future__ import annotations

import random

from conftest import salbp_dir
from opportune import load_plan
from opportune.engine.count import Counter
from opportune.engine.hub import HubPath, TailCounter
from opportune.engine.poset import bits
from opportune.engine.schedule import OrderEngine
from test_engine_hub import hub_shaped

ARC111_COUNT = int("10699784376412101459782493168195923005080661642039797082750047251791783909891289373479579282476892160000")


def _forced(poset, h) -> HubPath:
    """A hub path that uses hub ``h`` for every hard piece holding it (no plain attempt, no discovery)."""
    hp = HubPath(poset)
    hp.tails[h] = TailCounter(hp.counter, hp.poset.below[h])
    return hp


def test_persistent_hub_path_matches_plain_counter_along_successive_states():
    """States of a trial (remove a minimal element each step): the hub path with memos kept across
    calls gives the plain counter's counts and position sums, coupling or not."""
    rng = random.Random(5)
    hub_states = 0
    for trial in range(40):
        poset, h = hub_shaped(rng, rng.randint(3, 8), rng.randint(0, 6), rng.randint(1, 5), rng.randint(0, 3))
        plain = Counter(poset)
        hp = _forced(poset, h)
        s = poset.full
        while s:
            if hp.applies(s):
                hub_states += 1
                assert hp.count(s) == plain.count(s), (trial, s)
                sums = plain.position_sums(s)
                for x in rng.sample(list(bits(s)), min(3, s.bit_count())):
                    assert hp.position_sum(s, x) == sums[x], (trial, s, x)
            mins = [x for x in bits(s) if not poset.below[x] & s]
            s &= ~(1 << rng.choice(mins))
    assert hub_states > 100


def test_arc111_states_through_the_hub():
    """ARC111's plain count does not finish; the engine counts each state through task 91 exactly and
    fast once warm: count(S) = sum over the minimal m of count(S - m), an identity the hub path does not use."""
    engine = OrderEngine(load_plan(salbp_dir() / "ARC111.IN2"))
    every = engine.all_strategies
    # A warm-up cut short (the plain probe, then the hub search, stop at the deadline) is resumed,
    # not abandoned: the next count finds the hub and is exact.
    assert engine.warm_up(0.2) is False
    assert engine.warm_up(0.0) is False
    assert engine.count(0, every) == ARC111_COUNT
    assert any(hub is not None for hub in engine._hubs.values())
    rng = random.Random(2)
    mask = 0
    checked = 0
    for step in range(30):
        can = engine.installable_units(mask, every)
        if step % 6 == 5:
            nxt = [mask | u for u in (1 << i for i in bits(can))]
            assert engine.count(mask, every) == sum(engine.count(m, every) for m in nxt)
            checked += 1
        mask |= 1 << rng.choice(list(bits(can)))
    assert checked == 5
    assert engine._hub_state(mask, every)           # still before the hub: these went the hub way
