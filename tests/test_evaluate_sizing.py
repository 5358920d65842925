"""`opportune evaluate` sizes its work by the programmes that will run: the optimum's (compiled where the
core takes the plan) and the policy's own evaluation (none where the look-ahead decides by the optimum),
each with its measured speed and bytes (``EVALUATE_*`` in engine/tuning.py) and its own default cap."""

from __future__ import annotations

import json
import random
import re

import yaml
from typer.testing import CliRunner

from conftest import GEARBOX
from opportune import make_plan
from opportune.cli import evaluate as evaluate_cli
from opportune.engine import OrderEngine
from opportune.engine import tuning
from opportune.engine.tuning import EVALUATE_BYTES, EVALUATE_RATES
from opportune.policies.optimal import compiled_optimal_available, optimal_solver, optimum_engine

runner = CliRunner()


def app():
    from opportune.cli import app as the_app

    return the_app


def _text(out) -> str:
    return " ".join(out.output.split())


def _plan12():
    """12 parts, random precedences (seeded), two of them interchangeable: 40,398 states for the optimum at 2
    visible with an unlimited buffer, past the old default cap of 30,000 (the compiled optimum: milliseconds)."""
    rng = random.Random(2)
    ids = [f"p{i:02d}" for i in range(12)]
    requires = {ids[i]: [ids[j] for j in range(i) if rng.random() < 0.25] for i in range(12)}
    return make_plan(ids, {k: v for k, v in requires.items() if v})


def _file(tmp_path, plan) -> str:
    path = tmp_path / "plan12.yaml"
    path.write_text(yaml.safe_dump(plan.to_dict()))
    return str(path)


def test_the_refusal_quotes_the_programmes_that_would_run(monkeypatch):
    """On the same over-cap plan, the look-ahead (which decides by the optimum) and the paper's rule (whose
    evaluation runs look by look in Python) quote differently, each from its programme's constants."""
    rates = dict(EVALUATE_RATES, **{"compiled uniform": 50, "Python uniform": 40, "rule uniform": 89})
    monkeypatch.setattr(tuning, "EVALUATE_RATES", rates)
    engine = OrderEngine(__import__("opportune").load_plan(GEARBOX))
    compiled = compiled_optimal_available(optimum_engine(engine))
    rate, per_state = (50, EVALUATE_BYTES["compiled"]) if compiled else (40, EVALUATE_BYTES["Python"])
    texts = {}
    for policy in ("lookahead", "paper"):
        out = runner.invoke(app(), ["evaluate", str(GEARBOX), "--policy", policy, "--max-states", "2000"])
        assert out.exit_code == 1 and "Traceback" not in out.output, out.output
        texts[policy] = _text(out)
    for text in texts.values():
        # the optimum's states (of the merged plan: at least 2,001, the figure its estimate gives), at its rate
        states = int(re.search(r"needs (?:about |at least )?([\d,]+)", text).group(1).replace(",", ""))
        assert states > 2000 and f"more than --max-states 2,000; {'the compiled optimum' if compiled else ''}" in text
        assert f"{states / rate:.0f} s of CPU at ~{rate:,} states/s and about {max(1, states * per_state // 10**6)} MB" \
            in text, text
    assert "the policy decides by the optimum" in texts["lookahead"] and "~89 states/s" not in texts["lookahead"]
    assert "stops at 2,000 states (22 s of CPU at ~89 states/s)" in texts["paper"], texts["paper"]
    assert "decides by the optimum" not in texts["paper"]
    # where the core does not take the plan, the optimum in Python, quoted at its own rate and bytes
    monkeypatch.setattr(evaluate_cli._Work, "_compiled", staticmethod(lambda *args: False))
    text = _text(runner.invoke(app(), ["evaluate", str(GEARBOX), "--max-states", "2000"]))
    states = int(re.search(r"needs (?:about |at least )?([\d,]+)", text).group(1).replace(",", ""))
    assert (f"the optimum in Python (no compiled core): {states / 40:.0f} s of CPU at ~40 states/s and about "
            f"{max(1, states * EVALUATE_BYTES['Python'] // 10**6)} MB") in text, text


def test_a_plan_past_the_old_cap_is_evaluated_by_default_at_the_optimum(tmp_path):
    plan = _plan12()
    path = _file(tmp_path, plan)
    out = runner.invoke(app(), ["evaluate", path, "--visible", "2", "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.output)
    assert doc["states"] == doc["estimated_states"] == 40_398 and doc["estimate_exact"]     # past 30,000
    assert doc["policy_by_optimum"] and doc["expected_time"] == doc["optimal"] and doc["policy_states"] == 0
    # a second programme: the optimum of the plan as declared (its interchangeable parts not merged)
    whole = optimal_solver(OrderEngine(plan), visible=2, merge=False, max_states=10**6)
    assert abs(whole.value() - doc["optimal"]) < 1e-9 and whole.states > doc["states"]


def test_the_policys_own_evaluation_stops_at_its_default_cap(tmp_path, monkeypatch):
    """The paper's rule is evaluated look by look in Python: its default cap is its rate's share of the
    time (made small here), not the optimum's; it stops there and says how far it got."""
    monkeypatch.setattr(tuning, "EVALUATE_RATES", dict(EVALUATE_RATES, **{"rule uniform": 5}))
    cap = evaluate_cli.default_cap("rule uniform")
    assert cap == 5 * tuning.EVALUATE_SECONDS < evaluate_cli.default_cap("compiled uniform")
    out = runner.invoke(app(), ["evaluate", _file(tmp_path, _plan12()), "--policy", "paper"])
    text = _text(out)
    assert out.exit_code == 1 and "Traceback" not in out.output, text
    assert f"it stops if it passes --max-states {cap:,} (the default for the policy's own evaluation" in text, text
    assert f"needed more than --max-states {cap:,}" in text and f"stopped after {cap:,} of the policy's" in text


def test_default_caps_follow_the_measured_rates_and_memory():
    for programme, rate in EVALUATE_RATES.items():
        kind = "compiled" if programme.startswith("compiled") else "Python"
        cap = evaluate_cli.default_cap(programme)
        assert cap <= tuning.EVALUATE_SECONDS * rate and cap * EVALUATE_BYTES[kind] <= tuning.EVALUATE_MEMORY
    assert evaluate_cli.default_cap("compiled uniform") > 30_000 * 100     # the old flat cap, far below


def test_the_look_aheads_listing_stops_at_the_callers_deadline():
    """Without a budget the look-ahead lists its optimum's states by counted work; a caller's deadline
    (evaluate --time-limit) stops that listing too, as out of time (not as a different choice)."""
    import pytest

    from opportune import load_plan
    from opportune.engine.deadline import Deadline
    from opportune.policies.lookahead import Lookahead
    from opportune.policies.optimal import OutOfTime

    policy = Lookahead(visible=1, capacity=1)
    policy.deadline = Deadline.after(-1.0)
    with pytest.raises(OutOfTime):      # 2,777,988 states to list: stopped at once
        policy.decides_by_optimum(OrderEngine(load_plan("salbp:KILBRID")), 1, 1, None)
    gear = OrderEngine(load_plan(GEARBOX))
    policy = Lookahead(visible=1, capacity=1)
    policy.deadline = Deadline.after(3600.0)
    assert policy.decides_by_optimum(gear, 1, 1, None)


def test_in_the_pile_the_look_ahead_is_worth_the_pile_optimum_without_a_look_by_look_evaluation():
    """The look-ahead decides by the pile's optimum where it fits: evaluate takes the optimum's value for it
    (tests/test_pile_compiled.py checks it against its look-by-look evaluation) instead of evaluating it look
    by look in Python; the refusal of an over-cap pile plan quotes it so, and the paper's rule at its rate."""
    from opportune import load_plan
    from opportune.policies.pile import PileSolver

    out = runner.invoke(app(), ["evaluate", str(GEARBOX), "--bin", "pile", "--visible", "2", "--buffer-capacity",
                                "2", "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.output)
    assert doc["policy_by_optimum"] and doc["policy_states"] == 0 and doc["expected_time"] == doc["optimal"]
    python = PileSolver(OrderEngine(load_plan(GEARBOX)), visible=2, capacity=2, max_states=10**6)   # second method
    assert abs(python.value() - doc["optimal"]) < 1e-9 and python.states == doc["states"]
    texts = {policy: _text(runner.invoke(app(), ["evaluate", str(GEARBOX), "--bin", "pile", "--policy", policy,
                                                 "--max-states", "100"])) for policy in ("lookahead", "paper")}
    assert "the policy decides by the optimum" in texts["lookahead"], texts["lookahead"]
    rate = EVALUATE_RATES["rule pile"]
    assert f"stops at 100 states (under a second of CPU at ~{rate:,} states/s)" in texts["paper"], texts["paper"]


def test_the_answer_does_not_depend_on_how_far_the_listing_got_in_its_seconds(tmp_path, monkeypatch):
    """As on a loaded machine, the first listing stops at once: the estimate (47,131 on the merged plan) is over
    a cap of the exact count, so the listing goes on by counted work and the evaluation runs (it used to be
    refused on the estimate); under the count, refused as before, by the count."""
    import opportune.policies.states as states

    real = states.estimate_states

    def loaded(*args, **kwargs):
        if kwargs.get("time_limit") == 3.0:
            kwargs["time_limit"] = 1e-9
        return real(*args, **kwargs)

    monkeypatch.setattr(states, "estimate_states", loaded)
    path = _file(tmp_path, _plan12())
    out = runner.invoke(app(), ["evaluate", path, "--visible", "2", "--json", "--max-states", "40398"])
    assert out.exit_code == 0, out.output
    assert json.loads(out.output)["estimate_exact"] and json.loads(out.output)["states"] == 40_398
    out = runner.invoke(app(), ["evaluate", path, "--visible", "2", "--max-states", "30000"])
    assert out.exit_code == 1 and "at least 30," in _text(out)
