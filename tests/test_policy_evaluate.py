"""Exact policy evaluation (opportune.policies.evaluate) against independent values and Monte Carlo."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings

from conftest import GEARBOX, random_plans
from opportune import load_plan
from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.fixed import BufferFixed, planned_sequence
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.random_policy import RandomChoice
from opportune.study.simulate import StudyConfig, run_study

GEAR = load_plan(GEARBOX)


@pytest.mark.parametrize("capacity,paper,optimum", [
    (None, 13.7057, 13.5711),        # independent dynamic programmes (issue 13): +0.99%
    (1, 16.1236, 15.8398),           # +1.79% with one buffer location
    (2, 14.9791, 14.7494),           # +1.56% with two
])
def test_gearbox_paper_rule_and_optimum_match_independent_values(capacity, paper, optimum):
    ev = PolicyEvaluator(OrderEngine(GEAR), Opportunistic(), visible=2, capacity=capacity)
    assert round(ev.value(), 4) == paper
    assert round(ev.optimal(), 4) == optimum
    assert 0 < ev.policy_states <= ev.states


@settings(max_examples=25, deadline=None)
@given(plan=random_plans(max_parts=6, max_units=7, max_strategies=2))
def test_no_policy_beats_the_optimum(plan):
    engine = OrderEngine(plan)
    for policy in (Opportunistic(), BufferFixed(planned_sequence(engine))):
        for capacity in (None, 1):
            ev = PolicyEvaluator(engine, policy, visible=2, capacity=capacity)
            assert ev.value() >= ev.optimal() - 1e-9


@pytest.mark.parametrize("seed", [1, 2])
def test_exact_evaluation_equals_monte_carlo(seed):
    """The simulation of the same policy agrees within 4 standard errors (a second, independent method)."""
    import random

    from opportune import make_plan

    rng = random.Random(seed)
    ids = [f"p{i}" for i in range(7)]
    requires = {ids[j]: [ids[i] for i in range(j) if rng.random() < 0.3] for j in range(len(ids))}
    plan = make_plan(ids, {k: v for k, v in requires.items() if v})
    exact = PolicyEvaluator(OrderEngine(plan), Opportunistic(), visible=2, capacity=1).value()
    result = run_study(StudyConfig(plan=plan, strategies=("paper",), trials=3000, seed=seed,
                                   buffer_capacity=1), workers=1)
    times = [t.time for t in result.trials["paper"]]
    m = sum(times) / len(times)
    se = math.sqrt(sum((x - m) ** 2 for x in times) / (len(times) - 1) / len(times))
    assert abs(m - exact) <= 4 * se + 1e-9


def test_random_policies_are_refused():
    with pytest.raises(ValueError, match="random"):
        PolicyEvaluator(OrderEngine(GEAR), RandomChoice(), visible=2)


def test_evaluate_command_prints_both_values_and_refuses_what_it_cannot_do():
    import json

    from typer.testing import CliRunner

    from opportune.cli import app

    runner = CliRunner()
    out = runner.invoke(app, ["evaluate", str(GEARBOX), "--policy", "paper"])
    assert out.exit_code == 0, out.output
    assert "13.7057" in out.output and "13.5711" in out.output
    # without --policy: the default policy, the look-ahead, at the optimum on the gearbox
    out = runner.invoke(app, ["evaluate", str(GEARBOX), "--json"])
    doc = json.loads(out.output)
    assert doc["policy"] == "lookahead" and doc["ratio"] < 1.0005
    out = runner.invoke(app, ["evaluate", str(GEARBOX), "--buffer-capacity", "1", "--json", "--policy", "paper"])
    doc = json.loads(out.output)
    assert {"plan", "policy", "expected_time", "optimal", "ratio", "states"} <= set(doc)
    assert round(doc["expected_time"], 4) == 16.1236 and round(doc["optimal"], 4) == 15.8398
    assert abs(doc["ratio"] - doc["expected_time"] / doc["optimal"]) < 1e-12
    for args, code, words in ((["--bin", "conveyor"], 2, "uniform, weighted and pile"),
                              (["--policy", "random"], 2, "single decision rule"),
                              (["--policy", "nonsense"], 2, "choose from"),
                              (["--max-states", "10"], 1, "--max-states")):
        out = runner.invoke(app, ["evaluate", str(GEARBOX), *args])
        assert out.exit_code == code and words in out.output and "Traceback" not in out.output, out.output
