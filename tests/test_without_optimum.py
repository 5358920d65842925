"""The default policy with its exact optimum switched off (``Lookahead(optimal=False)``, ``evaluate
--without-optimum``): it never consults the optimum, decides by its fallback and says so, and is never
worth less than the optimum; with the optimum on, where it fits, it is worth exactly the optimum."""

import json

import pytest
import yaml
from conftest import benchmark
from typer.testing import CliRunner

from opportune import make_plan
from opportune.engine import OrderEngine
from opportune.policies import lookahead as lookahead_module
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.sequencer import Sequencer

runner = CliRunner()


def _chains(n: int):
    """n parts in two chains and a few cross links: few states whatever n."""
    ids = [f"p{i:02d}" for i in range(n)]
    requires = {ids[i]: [ids[i - 2]] + ([ids[i - 3]] if i % 5 == 0 else []) for i in range(3, n)}
    requires[ids[2]] = [ids[0]]
    return make_plan(ids, requires, name=f"chains-{n}")


@pytest.fixture
def optimum_calls(monkeypatch):
    """Every call of the look-ahead's optimum (its compiled or Python programme), recorded."""
    calls = []
    real = lookahead_module.optimal_solver

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(lookahead_module, "optimal_solver", spy)
    return calls


@pytest.mark.parametrize("n, capacity", [(10, 1), (18, 1)])   # the frontier window (the uniform bin)
def test_switched_off_it_never_consults_the_optimum_and_is_never_below_it(optimum_calls, n, capacity):
    engine = OrderEngine(_chains(n))
    settings = dict(visible=1, capacity=capacity)
    ev = PolicyEvaluator(engine, Lookahead(optimal=False, **settings), **settings)
    value = ev.value()
    assert optimum_calls == [] and not ev.by_optimum and ev.policy_states > 0
    assert value >= ev.optimal() - 1e-9
    on = PolicyEvaluator(engine, Lookahead(**settings), **settings)
    assert on.value() == ev.optimal() and on.by_optimum and len(optimum_calls) == 1


def test_switched_off_its_decisions_say_so():
    plan = _chains(20)
    policy = Lookahead(visible=2, capacity=2)
    seq = Sequencer(plan, policy=policy)
    assert policy.decide(seq.state, ("p05", "p01")).rule == Lookahead.OPTIMAL_RULE
    policy.optimal = False          # the programme chosen so far is dropped: the next decision chooses again
    rule = policy.decide(seq.state, ("p05", "p01")).rule
    assert rule.startswith("by its frontier window, because its exact optimum is switched off"), rule
    assert policy.refusal == Lookahead.SWITCHED_OFF and not policy._optimum


def _plan_file(tmp_path, plan):
    path = tmp_path / f"{plan.name}.yaml"
    path.write_text(yaml.safe_dump(plan.to_dict()))
    return str(path)


def test_evaluate_without_optimum_measures_the_fallback(tmp_path):
    from opportune.cli import app

    path = _plan_file(tmp_path, _chains(18))
    args = ["evaluate", path, "--visible", "1", "--buffer-capacity", "1"]
    on = runner.invoke(app, [*args, "--json"])
    off = runner.invoke(app, [*args, "--json", "--without-optimum"])
    assert on.exit_code == 0 and off.exit_code == 0, on.output + off.output
    on, off = json.loads(on.output), json.loads(off.output)
    assert on["policy_by_optimum"] and on["expected_time"] == on["optimal"] and on["estimated_policy_states"] == 0
    assert not off["policy_by_optimum"] and off["without_optimum"] and off["policy_states"] > 0
    assert off["optimal"] == on["optimal"] and off["expected_time"] >= off["optimal"] - 1e-9


def test_evaluate_says_the_policy_has_no_states_of_its_own_when_it_decides_by_the_optimum(tmp_path):
    from opportune.cli import app

    path = _plan_file(tmp_path, _chains(12))
    out = runner.invoke(app, ["evaluate", path, "--buffer-capacity", "1"])
    text = " ".join(out.output.split())
    assert out.exit_code == 0 and "none for the policy (it decides by the optimum's values" in text, text
    assert "at most" not in text, text
    out = runner.invoke(app, ["evaluate", path, "--buffer-capacity", "1", "--without-optimum"])
    text = " ".join(out.output.split())
    assert out.exit_code == 0 and "at most 257 for the policy" in text and "reached by the policy" in text, text
    assert "lookahead (its exact optimum switched off): expected time" in text, text


def test_without_optimum_is_refused_for_a_policy_without_one(tmp_path):
    from opportune.cli import app

    out = runner.invoke(app, ["evaluate", _plan_file(tmp_path, _chains(6)), "--policy", "paper", "--without-optimum"])
    assert out.exit_code == 2 and "'paper' has none" in " ".join(out.output.split()) and "Traceback" not in out.output


def test_the_lab_measures_the_fallback_beside_the_default(capsys):
    """benchmarks/policy_lab.py --without-optimum: a column 'fallback', never below the optimum, beside
    the default's (the optimum itself on plans where it fits)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    import policy_lab

    assert policy_lab.main(["--plans", "1", "--min-parts", "7", "--max-parts", "7", "--only", "r0-7", "--bins", "uniform",
                            "--visible", "1", "--capacities", "1", "--policies", "lookahead", "--without-optimum",
                            "--paired", ""]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("uniform, 1 visible, buffer 1: r0-7"))
    gaps = dict(part.strip().rsplit(" ", 1) for part in row.split("; ", 1)[1].split(","))
    assert set(gaps) == {"lookahead", "fallback"} and float(gaps["lookahead"].rstrip("%")) == 0.0
    assert float(gaps["fallback"].rstrip("%")) >= 0.0


def test_the_choice_of_the_optimum_does_not_depend_on_the_clock(monkeypatch):
    """Without a budget the states are listed by counted work: a clock that races (a loaded machine)
    changes nothing; with a budget the listing cut by the clock says so, not "more than the cap"."""
    import random

    from opportune.engine import deadline as deadline_module

    rng = random.Random(7)
    ids = [f"p{i}" for i in range(22)]
    plan = make_plan(ids, {b: [a for a in ids[:j] if rng.random() < 0.3] for j, b in enumerate(ids)})
    calm = Lookahead(visible=1, capacity=1)
    assert calm._optimum_fits(OrderEngine(plan)), calm.refusal
    clock = iter(range(0, 10 ** 9, 1000))           # a thousand seconds pass at every reading
    monkeypatch.setattr(deadline_module, "_perf", lambda: float(next(clock)))
    raced = Lookahead(visible=1, capacity=1)
    assert raced._optimum_fits(OrderEngine(plan)), raced.refusal
    budgeted = Lookahead(visible=1, capacity=1, budget=0.05)
    assert not budgeted._optimum_fits(OrderEngine(plan))
    assert "could not be listed" in budgeted.refusal and "more than" not in budgeted.refusal


def test_the_shared_programme_goes_with_its_engine():
    """The look-ahead's programme is shared by the look-aheads of one engine and freed with it: the
    programme holds the engine, so a table keyed weakly by the engine kept both alive forever."""
    import gc
    import weakref

    engine = OrderEngine(_chains(6))
    first, second = Lookahead(visible=1, capacity=1), Lookahead(visible=1, capacity=1)
    state = Sequencer(engine).state
    for policy in (first, second):
        policy.decide(state, ("p00",))
    assert first._evaluator is second._evaluator is not None
    alive = weakref.ref(engine)
    del engine, first, second, state, policy
    gc.collect()
    assert alive() is None


@pytest.mark.parametrize("visible, capacity", [(1, 1), (2, 1), (1, 2)])
def test_the_pile_diagnosis_sums_to_the_fallback_s_own_value(visible, capacity):
    """benchmarks/fallback_diagnosis.py --bin pile: along the fallback's path (each state's looks, fresh or
    left by a move, each met as often as its run meets it) the looks' costs sum to the fallback's exact
    value, computed by its own evaluation, and the terms where it acts otherwise than the optimum sum to its
    gap; windows of 2-3 parts on two-strategy plans of 7 parts, so the fallback is not the optimum."""
    import random

    from opportune.policies.pile import PileSolver

    pile_differences, random_plan = benchmark("fallback_diagnosis").pile_differences, benchmark("policy_lab").random_plan

    gaps = []
    for seed in range(3):
        engine = OrderEngine(random_plan(random.Random(seed), 7, 2, 0.3))
        fallback = Lookahead(optimal=False, visible=visible, capacity=capacity, bin="pile")
        fallback.window.sizes, fallback.window.max_states = (2, 3), 10 ** 6
        best, value, gap, rows = pile_differences(engine, visible, capacity, fallback)
        exact = PileSolver(engine, fallback, visible=visible, capacity=capacity).value()
        assert value == pytest.approx(exact, rel=1e-9) and best + gap == pytest.approx(value, rel=1e-9)
        assert all(row["advantage"] > 0 and row["looks"] > 0 for row in rows)
        gaps.append(gap)
    assert max(gaps) > 0.01 * best
