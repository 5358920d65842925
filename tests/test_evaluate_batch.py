"""The exact evaluation asks the policy for all the looks of a state at once and makes each move from its
action directly (:meth:`PolicyEvaluator.policy_moves_at`): the same value, to the last bit, as asking look
by look and matching the action among every legal move; and the moves are the ones the policy's own
``decide`` takes, as the sequencer reports them."""

from __future__ import annotations

import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import random_plans
from opportune import Sequencer, make_plan
from opportune.engine import OrderEngine
from opportune.policies.base import Action
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.optimal import same_action
from opportune.policies.variants import Slack


def look_by_look(engine, policy, **settings):
    """The evaluation as it was: the policy asked at each look in turn, its action matched among the legal
    moves, each look's successor solved before the next look is asked."""
    ev = PolicyEvaluator(engine, policy, **settings)
    ev.LOOKS_AT_ONCE = False
    ev.policy_moves_at = None           # never asked
    return ev


def _chains(n: int, seed: int):
    """n parts in chains with a few random cross links: beyond any window of 12 parts, few states."""
    rng = random.Random(seed)
    ids = [f"p{i:02d}" for i in range(n)]
    requires = {ids[i]: [ids[i - 2]] + ([ids[i - 3 - rng.randrange(3)]] if rng.random() < 0.3 and i > 5 else [])
                for i in range(3, n)}
    requires[ids[2]] = [ids[0]]
    return make_plan(ids, requires, name=f"chains-{n}-{seed}")


def _policies(visible, capacity):
    return [Opportunistic(), Slack(), Lookahead(optimal=False, visible=visible, capacity=capacity)]


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=6, max_units=7, max_strategies=2), visible=st.integers(1, 3),
       capacity=st.sampled_from([1, 2, None]))
def test_all_looks_at_once_give_the_value_look_by_look_gives_to_the_bit(plan, visible, capacity):
    engine = OrderEngine(plan)
    for policy, again in zip(_policies(visible, capacity), _policies(visible, capacity)):
        settings_ = dict(visible=visible, capacity=capacity)
        batch = PolicyEvaluator(engine, policy, **settings_)
        batch.OPTIMUM_SHORTCUT = False          # the look-ahead evaluated look by look, not by its optimum's value
        one = look_by_look(engine, again, **settings_)
        one.OPTIMUM_SHORTCUT = False
        assert batch.value() == one.value()
        assert batch.policy_states == one.policy_states


@pytest.mark.parametrize("n, visible, capacity, seed", [(16, 1, 1, 0), (14, 2, 1, 1), (13, 3, 1, 2), (13, 1, 2, 3)])
def test_the_fallback_beyond_its_window_is_worth_the_same_either_way(n, visible, capacity, seed):
    engine = OrderEngine(_chains(n, seed))
    settings_ = dict(visible=visible, capacity=capacity)
    batch = PolicyEvaluator(engine, Lookahead(optimal=False, **settings_), **settings_)
    one = look_by_look(engine, Lookahead(optimal=False, **settings_), **settings_)
    assert batch.value() == one.value() and not batch.by_optimum
    assert batch.policy.window.work["windows"] > 0      # the window decided (the plan is beyond one window)


def _walk(engine, policy, visible, capacity, steps, rng):
    """States the policy reaches, as the sequencer keeps them, on random looks: ``(state, look)`` pairs."""
    seq = Sequencer(engine, policy, buffer_capacity=capacity, budget=None)
    out = []
    for _ in range(steps):
        state = seq.state
        if state.is_complete:
            break
        units = [p for p, c in state.in_bin.items() for _ in range(c)]
        look = tuple(rng.sample(units, min(visible, len(units))))
        out.append((state, look))
        seq.state, seq.pending = state, None
        if seq.decide(look).action.kind != "shake":
            seq.report("success")
    return out


@pytest.mark.parametrize("n, visible, capacity, seed", [(16, 2, 2, 0), (17, 1, 1, 1), (15, 3, 1, 2)])
def test_the_moves_it_evaluates_are_those_the_policy_decides(n, visible, capacity, seed):
    """On sampled states the policy reaches (a walk through the sequencer), every look's move in the
    evaluation is the move of the action ``decide`` takes, to the state the sequencer reports after it."""
    rng = random.Random(seed)
    engine = OrderEngine(_chains(n, seed))
    evaluated = PolicyEvaluator(engine, Lookahead(optimal=False, visible=visible, capacity=capacity),
                                visible=visible, capacity=capacity)
    deciding = Lookahead(optimal=False, visible=visible, capacity=capacity)
    checked = 0
    for state, _ in _walk(engine, deciding, visible, capacity, 40, rng):
        sched = state.schedule
        key = evaluated.policy_key(sched.mask, sched.consistent, state.buffer)
        looks = [look for look, _ in evaluated._looks(evaluated._bin_counts(evaluated._counts_key(key)))]
        for look, move in zip(looks, evaluated.policy_moves_at(key, looks)):
            seq = Sequencer(engine, deciding, buffer_capacity=capacity, budget=None)
            seq.state, seq.pending = state, None
            action = seq.decide(tuple(evaluated.ids[i] for i in look)).action
            if action.kind == "shake":
                assert move is None
                continue
            after = seq.report("success").schedule
            assert move[1] == evaluated.policy_key(after.mask, after.consistent, seq.state.buffer)
            assert move[0] == evaluated.move[engine.plan.index(action.part)]
            checked += 1
    assert checked > 50


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=5, max_units=6, max_strategies=2), capacity=st.sampled_from([1, 2, None]),
       ordered=st.booleans(), data=st.data())
def test_a_move_made_from_its_action_is_the_legal_move_of_that_action(plan, capacity, ordered, data):
    """Every action, legal or not, at states along a walk: the legal ones give the move :meth:`policy_moves`
    lists for them; the others are refused as the matching refused them."""
    engine = OrderEngine(plan)
    ev = PolicyEvaluator(engine, Opportunistic() if ordered else Slack(), visible=2, capacity=capacity)
    key = ev.policy_start()
    for _ in range(data.draw(st.integers(0, 6))):
        if key[0] == engine.full:
            break
        looks = [look for look, _ in ev._looks(ev._bin_counts(ev._counts_key(key)))]
        look = data.draw(st.sampled_from(looks))
        legal = list(ev.policy_moves(key, look))
        for i, part in enumerate(ev.ids):
            for action in (Action("install", part, "bin"), Action("buffer", part), Action("install", part, "buffer")):
                match = [m for m in legal if same_action(m[2], action)]
                if match:
                    assert ev._move_of(key, look, action) == match[0][:2]
                else:
                    with pytest.raises(ValueError, match="not a legal move"):
                        ev._move_of(key, look, action)
        if not legal:
            break
        key = data.draw(st.sampled_from(legal))[1]


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=5, max_units=6, max_strategies=2), visible=st.integers(1, 2),
       capacity=st.sampled_from([1, None]), seed=st.integers(0, 99))
def test_in_a_weighted_bin_too(plan, visible, capacity, seed):
    """A bin whose parts are seen with different chances (a weighted bin, its looks enumerated): the same."""
    rng = random.Random(seed)
    weights = {p.id: rng.choice([0.5, 1.0, 2.0]) for p in plan.parts}
    engine = OrderEngine(plan)
    for make in (Slack, lambda: Lookahead(optimal=False, visible=visible, capacity=capacity, weights=weights)):
        settings_ = dict(visible=visible, capacity=capacity, weights=weights)
        assert (PolicyEvaluator(engine, make(), **settings_).value()
                == look_by_look(engine, make(), **settings_).value())
