"""The compiled pile optimum (src/native/pile.cpp, CompiledPileSolver) against the Python programme
(PileSolver): the same doubles on random plans in every setting, the same states, the fallback, the
state cap, the deadline and bad input."""

from __future__ import annotations

import random

import pytest
from conftest import GEARBOX, random_plans
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.planning.costs import TimeModel
from opportune.policies.optimal import OptimalTooLarge, OutOfTime
from opportune.policies.pile import (
    CompiledPileSolver,
    PileSolver,
    compiled_pile_available,
    pile_solver,
)
from opportune.policies.states import estimate_states

GEAR = OrderEngine(load_plan(GEARBOX))
pytestmark = pytest.mark.skipif(not compiled_pile_available(GEAR), reason="the compiled core is not built")


def _costs(plan, seed: int) -> TimeModel:
    rng = random.Random(seed)
    return TimeModel(shake=rng.choice([0.5, 1.0, 2.7]), look=rng.choice([0.0, 0.3]),
                     parts={p.id: rng.choice([1.0, 1.7, 0.35]) for p in plan.parts})


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=5, max_units=7, max_strategies=2), seed=st.integers(0, 1000))
def test_the_compiled_optimum_gives_the_same_doubles_as_python(plan, seed):
    """Every setting (1-3 visible, 1, 2 or unlimited buffer locations, one or two strategies, uneven
    costs): the value at the start, at every window of the start and after a shake elsewhere, bit for
    bit, and the same number of stored values."""
    engine = OrderEngine(plan)
    costs = _costs(plan, seed)
    for visible in (1, 2, 3):
        for capacity in (1, 2, None):
            py = PileSolver(engine, visible=visible, capacity=capacity, costs=costs)
            cc = CompiledPileSolver(engine, visible=visible, capacity=capacity, costs=costs)
            assert cc.value() == py.value(), (visible, capacity)
            assert cc.states == py.states
            start = py.start_key()
            for window, _ in py._looks(py._bin_counts(start)):
                assert cc._window_value(start, window) == py._window_value(start, window)
                for _, nxt, action in py._moves(start, window):
                    assert cc._after(start, window, action, nxt) == py._after(start, window, action, nxt)


def test_the_gearbox_in_every_setting_and_the_estimate_is_the_count():
    """The gearbox (two strategies): bit for bit, and the state count listed before the work is the
    count the compiled programme stores."""
    for visible in (1, 2, 3):
        for capacity in (1, 2, None):
            cc = CompiledPileSolver(GEAR, visible=visible, capacity=capacity)
            value = cc.value()
            assert value == PileSolver(GEAR, visible=visible, capacity=capacity).value()
            assert cc.states == estimate_states(GEAR, visible=visible, capacity=capacity, pile=True).states
            assert 0 < cc.bytes <= 2 * 64 * cc.states        # 64 bytes a value in the table, the pairs beside


def test_the_factory_picks_the_compiled_optimum_and_python_for_a_policy(monkeypatch):
    from opportune.policies.opportunistic import Opportunistic

    compiled = pile_solver(GEAR, visible=2)
    assert type(compiled) is CompiledPileSolver
    assert type(pile_solver(GEAR, Opportunistic())) is PileSolver
    from opportune.policies import pile

    monkeypatch.setattr(pile, "_native", None)         # what OPPORTUNE_PURE_PYTHON=1 or no build gives
    fallback = pile_solver(GEAR, visible=2)
    assert type(fallback) is PileSolver
    assert fallback.value() == compiled.value()
    with pytest.raises(ValueError, match="compiled core"):
        CompiledPileSolver(GEAR)


def test_the_pure_python_switch_turns_the_core_off():
    """OPPORTUNE_PURE_PYTHON=1 in a fresh interpreter: the factory gives the Python programme, same value."""
    import subprocess
    import sys

    code = ("from opportune import load_plan; from opportune.engine import OrderEngine; "
            "from opportune.policies.pile import pile_solver; "
            f"s = pile_solver(OrderEngine(load_plan({str(GEARBOX)!r})), capacity=1); print(type(s).__name__, repr(s.value()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**__import__("os").environ, "OPPORTUNE_PURE_PYTHON": "1"}).stdout.split()
    assert out == ["PileSolver", repr(CompiledPileSolver(GEAR, capacity=1).value())]


def test_the_state_cap_is_respected_and_the_work_goes_on_after_it_is_raised():
    full = estimate_states(GEAR, visible=2, capacity=2, pile=True).states
    cc = CompiledPileSolver(GEAR, visible=2, capacity=2, max_states=full // 3)
    with pytest.raises(OptimalTooLarge, match="more than"):
        cc.value()
    assert cc.states <= full // 3
    cc.max_states = full
    assert cc.value() == PileSolver(GEAR, visible=2, capacity=2).value()
    assert cc.states == full
    exact = CompiledPileSolver(GEAR, visible=2, capacity=2, max_states=full)
    exact.reserve(full)
    assert exact.value() == cc.value() and exact.states == full


def test_a_passed_deadline_stops_and_keeps_what_was_finished():
    cc = CompiledPileSolver(GEAR, visible=3)
    cc.deadline = Deadline.after(-1.0)
    with pytest.raises(OutOfTime):
        cc.value()
    cc.deadline = None
    assert cc.value() == PileSolver(GEAR, visible=3).value()


def test_bad_input_is_a_message():
    cc = CompiledPileSolver(GEAR, visible=2)
    n = len(GEAR.plan.parts)
    with pytest.raises(ValueError, match="one count per part"):
        cc._shake_value((0, GEAR.all_strategies, (0,) * (n + 1)))
    with pytest.raises(ValueError, match="out of range"):
        cc._window_value(cc.start_key(), (0, n))
    with pytest.raises(ValueError, match="optimum only"):
        from opportune.policies.opportunistic import Opportunistic

        CompiledPileSolver(GEAR, Opportunistic())
    one = OrderEngine(make_plan(["a"], {}))          # the smallest plan: one look, one move
    assert CompiledPileSolver(one, visible=1).value() == PileSolver(one, visible=1).value() == 1.0


def test_the_look_ahead_uses_the_compiled_optimum_up_to_its_cap(monkeypatch):
    """Past the Python cap (1,000 states here) the compiled optimum decides, so the look-ahead's exact value is
    the optimum's; with the compiled cap under the count the pile's frontier window decides instead."""
    from opportune.policies.lookahead import Lookahead

    count = estimate_states(GEAR, visible=2, capacity=2, pile=True).states
    ahead = Lookahead(visible=2, capacity=2, bin="pile", max_states=1_000)
    assert 1_000 < count <= Lookahead.COMPILED_STATES
    value = PileSolver(GEAR, ahead, visible=2, capacity=2, max_states=10 * count).value()
    assert type(ahead._evaluator) is CompiledPileSolver and ahead._evaluator.states == count
    assert ahead._evaluator.max_states == Lookahead.COMPILED_STATES
    assert abs(value - CompiledPileSolver(GEAR, visible=2, capacity=2).value()) < 1e-9
    monkeypatch.setattr(Lookahead, "COMPILED_STATES", count - 1)
    step = Lookahead(visible=2, capacity=2, bin="pile", max_states=count - 1)
    step.choose_at(GEAR, 0, GEAR.all_strategies, (), 2, tuple(GEAR.plan.part_ids[:2]))
    assert step._evaluator is None and step.window.work["windows"] > 0 and step.window.work["by_base"] == 0


def test_a_budgeted_look_ahead_stops_the_compiled_optimum_at_its_deadline():
    """A decision whose budget is spent stores no state of the compiled optimum (counted work, not the
    clock) and is the base's; without a budget the first decision solves the whole programme (a warm-up)."""
    from opportune.policies.lookahead import Lookahead

    look = tuple(GEAR.plan.part_ids[:3])
    spent = Lookahead(visible=3, bin="pile", budget=10.0)
    assert type(spent._values(GEAR)) is CompiledPileSolver      # counted and reserved, nothing solved yet
    spent.lookahead_budget = 1e-9                               # then a decision with its budget spent
    action = spent.choose_at(GEAR, 0, GEAR.all_strategies, (), float("inf"), look)
    assert action == spent.fallback.choose_at(GEAR, 0, GEAR.all_strategies, (), float("inf"), look)
    assert type(spent._evaluator) is CompiledPileSolver and spent._evaluator.states == 0
    whole = Lookahead(visible=3, bin="pile", max_states=1_000)
    whole.choose_at(GEAR, 0, GEAR.all_strategies, (), float("inf"), look)
    assert whole._evaluator.states == estimate_states(GEAR, visible=3, pile=True).states


def test_the_lab_gives_the_same_results_with_the_compiled_optimum(tmp_path, capsys):
    """benchmarks/policy_lab.py --only and --python-optimum: the named plans alone, the same optimum and gaps by
    the Python programme as by the compiled one (the lab's default)."""
    import json
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import policy_lab

    runs = []
    for extra in (["--python-optimum"], []):
        out = tmp_path / f"lab{len(runs)}.jsonl"
        assert policy_lab.main(["--plans", "3", "--only", "r2-8x2", "--bins", "pile", "--visible", "1",
                                "--capacities", "1", "--policies", "slack,lookahead", "--paired", "",
                                "--results", str(out), *extra]) in (0, None)
        runs.append([{k: v for k, v in json.loads(line).items() if k != "cpu"} for line in out.read_text().splitlines()])
    assert [r["plan"] for r in runs[0]] == ["r2-8x2"]
    assert runs[0] == runs[1] and runs[0][0]["gaps"]["slack"] > runs[0][0]["gaps"]["lookahead"] - 1e-12
    with pytest.raises(SystemExit):
        policy_lab.main(["--plans", "3", "--only", "r99", "--paired", ""])
    assert "no plan named r99" in capsys.readouterr().err
