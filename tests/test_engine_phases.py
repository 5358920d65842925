"""The counting phases behind ``Schedule.count_result``: each says why it stopped, and the count they
give together is the brute-force count whichever phase gives it."""

from __future__ import annotations

import math
from itertools import permutations

from opportune import make_plan
from opportune.engine.deadline import Deadline
from opportune.engine.phases import PHASES, CountQuestion, ExactTurns, StopReason, count_in_phases
from opportune.engine.schedule import OrderEngine, Schedule

REQUIRES = {"c": ["a"], "d": ["a", "b"], "f": ["e"]}
PARTS = ["a", "b", "c", "d", "e", "f"]


def brute_force() -> int:
    return sum(all(order.index(r) < order.index(p) for p, rs in REQUIRES.items() for r in rs)
               for order in permutations(PARTS))


def question(engine: OrderEngine) -> CountQuestion:
    return CountQuestion.ask(Schedule(engine), 0.01, 10.0, 0, 0.65, Deadline.NEVER, 1)


def test_the_exact_phase_counts_a_small_plan_and_says_so():
    q = question(OrderEngine(make_plan(PARTS, REQUIRES)))
    result = ExactTurns().run(q, Deadline(q.exact_end))
    assert result.stop is StopReason.EXACT
    assert result.answer.exact and result.answer.value == brute_force()


def test_a_memo_budget_stops_the_exact_phase_and_a_later_phase_still_counts():
    """One memo entry per count: the exact turns stop on memory (not the clock), the relaxation phase
    has nothing to go on with, and the estimate's phase (its runs finish the small pieces exactly)
    states the count with no error."""
    q = question(OrderEngine(make_plan(PARTS, REQUIRES), max_memo=1))
    assert ExactTurns().run(q, Deadline(q.exact_end)).stop is StopReason.OUT_OF_MEMORY
    q.grace()
    reasons = [phase.run(q, q.end).stop for phase in PHASES[1:3]]
    assert reasons == [StopReason.SKIPPED, StopReason.ESTIMATED]
    answer = count_in_phases(question(OrderEngine(make_plan(PARTS, REQUIRES), max_memo=1)))
    assert not answer.exact and answer.rel_error == 0.0
    assert abs(answer.value - brute_force()) <= 1e-9 * brute_force()


def test_without_time_the_phases_answer_with_an_interval_around_the_count():
    """A deadline already passed: whatever the phases managed, the answer holds the true count."""
    engine = OrderEngine(make_plan(PARTS, REQUIRES), max_memo=1)
    q = CountQuestion.ask(Schedule(engine), 0.01, 0.0, 0, 0.65, Deadline(0.0), 1)
    answer = count_in_phases(q)
    low, high = answer.interval_log10
    assert low - 1e-9 <= math.log10(brute_force()) <= high + 1e-9
