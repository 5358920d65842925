"""`opportune evaluate` knows its size before it starts: the state count, the refusal, the deadline,
the progress report, bounded memory (policies/states.py, the bounds of policies/optimal.py)."""

from __future__ import annotations

import io
import itertools
import json

import pytest
from hypothesis import HealthCheck, given, settings
from typer.testing import CliRunner

from conftest import GEARBOX, random_plans
from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.engine.downsets import count_downsets
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.optimal import LOOK_CACHE_LOOKS, OptimalSolver, OptimalTooLarge, OutOfTime
from opportune.policies.pile import PileSolver
from opportune.policies.states import downset_profile, estimate_from_downsets, estimate_states

GEAR = load_plan(GEARBOX)
runner = CliRunner()


def _solved(engine, *, pile: bool, **settings):
    solver = (PileSolver if pile else OptimalSolver)(engine, **settings)
    solver.value()
    return solver


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=4, max_units=5, max_strategies=2))
def test_the_listed_count_is_the_number_of_states_the_programme_stores(plan):
    """Exact where the listing finishes: the optimum's programme, run to the end, stores exactly as many."""
    engine = OrderEngine(plan)
    for capacity in (None, 1):
        for pile in (False, True):
            for visible in (1, 2):
                solver = _solved(engine, pile=pile, visible=visible, capacity=capacity)
                est = estimate_states(engine, visible=visible, capacity=capacity, pile=pile)
                assert est.exact and est.states == est.low == solver.states, (capacity, pile, visible)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=5, max_units=6, max_strategies=3))
def test_the_downset_estimate_is_within_its_stated_factor(plan):
    """Exact for one strategy of single units; otherwise within a factor 16 (the module's docstring)."""
    engine = OrderEngine(plan)
    single = engine.k == 1 and all(p.quantity == 1 for p in plan.parts)
    for capacity in (None, 0):
        for pile in (False, True):
            true = _solved(engine, pile=pile, visible=2, capacity=capacity).states
            guess = estimate_from_downsets(engine, visible=2, capacity=capacity, pile=pile)
            if single:
                assert guess == true
            else:
                assert true / 16 <= guess <= 16 * true


@settings(max_examples=40, deadline=None)
@given(plan=random_plans(max_parts=7, max_units=7, max_strategies=1, quantities=False))
def test_the_downset_profile_counts_the_downsets_by_size(plan):
    poset = OrderEngine(plan).posets[0]
    profile = downset_profile(poset)
    assert sum(profile) == count_downsets(poset)          # a second, independent method
    assert profile[0] == profile[-1] == 1                  # the whole set, and the empty one


def test_a_large_plan_is_estimated_cheaply_and_the_listing_stops_at_the_limit():
    engine = OrderEngine(load_plan("salbp:KILBRID"))
    est = estimate_states(engine, visible=2, capacity=1, stop_above=10_000)
    assert not est.exact and est.over(10_000)
    assert 10_000 < est.low <= est.states                  # what was listed is a proven lower bound
    assert est.keys <= 10_001
    # no listing possible at all: one state per buffer content of the start already passes the limit
    est = estimate_states(engine, visible=2, capacity=None, stop_above=10_000)
    assert est.low >= 2 ** 45 and est.keys == 1 and "about" in est.describe()


def test_the_refusal_comes_before_any_state_is_expanded(monkeypatch):
    """Counted work: no look, no move, no policy preparation happens before the refusal."""
    import opportune.study.simulate

    def forbidden(*args, **kwargs):
        raise AssertionError("the programme started")

    monkeypatch.setattr(OptimalSolver, "_moves", forbidden)
    monkeypatch.setattr(OptimalSolver, "_look_distribution", forbidden)
    monkeypatch.setattr(opportune.study.simulate, "prepare", forbidden)
    for args in (["salbp:KILBRID"], ["salbp:KILBRID", "--bin", "pile"], ["salbp:ARC111", "--buffer-capacity", "1"],
                 [str(GEARBOX), "--max-states", "2492"]):
        out = runner.invoke(app(), ["evaluate", *args])
        assert out.exit_code == 1, out.output
        assert "Traceback" not in out.output and "AssertionError" not in out.output
        text = " ".join(out.output.split())
        assert "more than --max-states" in text and "opportune simulate" in text, text
    # the count (of the plan with its interchangeable parts merged, which the optimum solves), and the limit
    assert "at least 2,493) states for the optimum, more than --max-states 2,492" in text


def test_the_refusal_in_json_is_an_error_document():
    out = runner.invoke(app(), ["evaluate", "salbp:KILBRID", "--json"])
    assert out.exit_code == 1
    doc = json.loads(out.output)
    assert "--max-states" in doc["error"]["message"]


def test_the_evaluation_reports_its_estimate_and_the_answers_are_unchanged():
    """The values themselves are those of tests/test_policy_evaluate.py (unchanged); here, the count."""
    out = runner.invoke(app(), ["evaluate", str(GEARBOX), "--policy", "paper", "--json", "--buffer-capacity", "1"])
    doc = json.loads(out.output)
    assert round(doc["expected_time"], 4) == 16.1236 and round(doc["optimal"], 4) == 15.8398
    # the optimum's states are the merged plan's (169; 218 as declared, which bound the policy's)
    assert doc["estimate_exact"] and doc["estimated_states"] == doc["states"] == 169
    assert doc["policy_states"] <= doc["estimated_policy_states"] == 218


@pytest.mark.parametrize("pile", [False, True])
def test_the_programme_stops_at_its_deadline_and_goes_on_from_there(pile):
    engine = OrderEngine(load_plan("salbp:MERTENS"))
    policy = Opportunistic()
    fresh = (PileSolver(engine, policy, capacity=1) if pile else PolicyEvaluator(engine, policy, capacity=1)).value()
    ev = PileSolver(engine, policy, capacity=1) if pile else PolicyEvaluator(engine, policy, capacity=1)
    ev.deadline = Deadline.after(-1.0)
    with pytest.raises(OutOfTime):
        ev.value()
    stored = ev.states if pile else ev.policy_states
    assert stored <= 64                                   # read between states: at most 64 more
    ev.deadline = None
    assert ev.value() == fresh                            # nothing finished is lost, nothing wrong is kept


def test_the_state_limit_and_the_progress_report():
    engine = OrderEngine(GEAR)
    ev = PolicyEvaluator(engine, Opportunistic(), capacity=1, max_states=100)
    seen = []
    ev.progress = lambda solver: seen.append(solver.policy_states)
    with pytest.raises(OptimalTooLarge):
        ev.value()
    assert ev.policy_states == 100 and seen == sorted(seen) and seen[-1] == 64


def test_a_plan_with_too_many_looks_per_state_is_refused_whatever_the_state_limit(tmp_path):
    """A chain of 1,000 parts has few states (1,001 with no buffer) but ~500,000 looks at each."""
    import yaml

    ids = [f"p{i}" for i in range(1000)]
    plan = make_plan(ids, {b: [a] for a, b in itertools.pairwise(ids)})
    est = estimate_states(OrderEngine(plan), capacity=0, time_limit=None)   # the count, not its speed
    assert est.exact and est.states == 1001 and est.looks == 1000 * 999 // 2
    path = tmp_path / "chain.yaml"
    path.write_text(yaml.safe_dump(plan.to_dict()))
    out = runner.invoke(app(), ["evaluate", str(path), "--buffer-capacity", "0", "--max-states", "10000000"])
    text = " ".join(out.output.split())
    assert out.exit_code == 1 and "499,500 distinct looks" in text and "opportune simulate" in text, text


def test_the_look_cache_is_bounded_by_looks_not_by_states():
    solver = OptimalSolver(OrderEngine(load_plan("salbp:KILBRID")), visible=2)
    looks_per_bin = 45 * 46 // 2
    assert solver._looks.cache_info().maxsize * looks_per_bin <= LOOK_CACHE_LOOKS


def test_the_cli_stops_at_its_time_limit_and_says_how_far_it_got():
    out = runner.invoke(app(), ["evaluate", str(GEARBOX), "--time-limit", "0"])
    assert out.exit_code == 1 and "Traceback" not in out.output
    text = " ".join(out.output.split())
    assert "--time-limit 0 s" in text and "stopped after" in text and "2,493 (exact)" in text, text


def test_a_progress_bar_only_on_a_terminal(monkeypatch, tmp_path):
    import yaml
    from rich.console import Console

    from opportune.cli import common

    path = tmp_path / "x.yaml"
    path.write_text(yaml.safe_dump(make_plan(["a", "b", "c"], {"c": ["a"]}).to_dict()))
    out = runner.invoke(app(), ["evaluate", str(path), "--policy", "paper"])    # not a terminal: no bar
    assert out.exit_code == 0 and "states" in out.output and "━" not in out.output
    err = io.StringIO()
    monkeypatch.setattr(common, "_consoles", {"out": Console(file=io.StringIO(), force_terminal=True),
                                              "err": Console(file=err, force_terminal=True)})
    out = runner.invoke(app(), ["evaluate", str(path), "--policy", "paper"])
    assert out.exit_code == 0, out.output
    assert "optimum" in err.getvalue() and "states" in err.getvalue()


def app():
    from opportune.cli import app as the_app

    return the_app


def test_the_look_aheads_own_programme_stops_at_the_evaluations_time_limit(tmp_path):
    """The default policy (the look-ahead) runs a programme of its own at every decision; on a plan of
    16 parts that programme alone takes minutes.  It stops with the evaluation (measured in the CPU
    time of a child process: the machine may be busy), and says so rather than deciding otherwise."""
    import random
    import resource
    import subprocess
    import sys

    import yaml

    rng = random.Random(3)
    requires = {f"p{i}": [f"p{j}" for j in range(i) if rng.random() < 0.12] for i in range(16)}
    path = tmp_path / "p16.yaml"
    path.write_text(yaml.safe_dump({"name": "p16", "parts": [f"p{i}" for i in range(16)],
                                    "strategies": [{"name": "s", "requires": {k: v for k, v in requires.items() if v}}]}))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([sys.executable, "-m", "opportune.cli", "evaluate", str(path), "--time-limit", "1",
                          "--max-states", "100000000"], capture_output=True, text=True, timeout=600)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    assert out.returncode == 1 and "passed --time-limit 1 s" in out.stderr, out.stderr
    assert cpu < 20, cpu        # without the bound: more than 80 s of CPU
