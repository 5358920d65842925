"""The words and numbers the dashboard shows, written by the service.

* Counts for people (:func:`~opportune.policies.printable.count_label`): in full with grouped digits up
  to 15 digits, else three significant digits and the exponent, checked against :mod:`decimal`'s own
  rounding at every size, from an int or from the text the service keeps a count as.
* The explanation the service writes (``explain``) names every count so: no number longer than 15
  digits, on KILBRID's counts of 30 digits and expected positions of 23-digit fractions.
* One statement of how sure an estimated decision is: a near tie, or its probability of being the exact
  rule's choice, never both.
* A complete run's totals (``run_totals``) against the same totals counted while driving the run.
"""

from __future__ import annotations

import random
import re
from decimal import ROUND_HALF_UP, Context

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.engine.schedule import count_text, decimal
from opportune.policies.base import Action, Decision, Estimate
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.printable import LABEL_DIGITS, count_label
from opportune.sequencer import Sequencer
from opportune.service.views import decision_view, run_totals

LONGEST = re.compile(r"\d[\d,]*")   # a number as text shows it (grouped digits included)


def label_by_decimal(n: int) -> str:
    """The label by a second method: the decimal module's rounding to three significant digits."""
    digits = decimal(n)
    if len(digits) <= LABEL_DIGITS:
        return f"{n:,}"
    d = Context(prec=3, rounding=ROUND_HALF_UP, Emax=10**9).create_decimal(digits)
    sign, mantissa, exponent = d.as_tuple()
    m = "".join(map(str, mantissa)).ljust(3, "0")
    return f"{m[0]}.{m[1:3]}e{exponent + len(mantissa) - 1}"


def longest_number(text: str) -> int:
    return max((len(m.replace(",", "")) for m in LONGEST.findall(text)), default=0)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.integers(0, 10**20), st.integers(1, 6_000).flatmap(lambda d: st.integers(10 ** (d - 1), 10**d - 1)),
                 st.integers(14, 5_000).map(lambda e: 10**e - 1), st.integers(14, 5_000).map(lambda e: 9995 * 10**e),
                 st.integers(14, 5_000).map(lambda e: 9994999 * 10**e)))
def test_a_count_is_labelled_as_decimal_rounds_it_from_an_int_or_the_services_text(n):
    label = count_label(n)
    assert label == label_by_decimal(n)
    assert count_label(count_text(n)) == label          # the text the service keeps (rounded past 4,300 digits)
    if n < 10**4000:
        assert count_label(decimal(n)) == label          # plain digits, as a run's row keeps them
    assert longest_number(label) <= LABEL_DIGITS


def test_count_labels_at_their_edges():
    assert [count_label(n) for n in (0, 7, 336, 40_320, 10**15 - 1, 10**15, 10**15 + 5 * 10**12)] == \
        ["0", "7", "336", "40,320", "999,999,999,999,999", "1.00e15", "1.01e15"]
    assert count_label(613 * 10**96 + 4999 * 10**92) == "6.13e98"     # not 6.14e98: the 4th digit is 4
    assert count_label(9995 * 10**100) == "1.00e104"                    # rounding carries into the exponent
    assert count_label("2.8462596809170545e+35659") == "2.85e35659"
    for bad in ("-1", "12a", "", "1e", "１２"):
        with pytest.raises(ValueError, match="not a count"):
            count_label(bad)
    with pytest.raises(ValueError, match="not negative"):
        count_label(-1)


def test_the_services_explanations_write_no_number_longer_than_15_digits():
    """KILBRID: 1.98e29 completions, expected positions whose exact fractions have 23-digit terms.  The
    explanation names each count as its label; the JSON keeps the exact counts."""
    plan = load_plan("salbp:KILBRID")
    seq = Sequencer(plan, budget=None)
    seen = {"buffer": 0, "install": 0}
    rng = random.Random(4)
    while sum(seen.values()) < 12:
        in_bin = [p for p, k in seq.state.in_bin.items() for _ in range(k)]
        look = rng.sample(in_bin, min(3, len(in_bin)))
        row = seq.decide(look)
        view = decision_view(row)
        text = view["explain"]
        assert longest_number(text) <= LABEL_DIGITS, text
        for c in view["candidates"]:
            assert f"keeps {count_label(int(c['options']))} of {count_label(int(c['total']))} completions" in text
            assert len(c["options"]) > LABEL_DIGITS or c["options"] in text.replace(",", "")
        for p in view["positions"]:
            assert f"visible {p['part']}: expected position {p['expected']:.3f}" in text
            exact = p["exact"].split("/")
            assert (f"({p['exact']})" in text.replace(",", "")) == (max(map(len, exact)) <= LABEL_DIGITS)
        seen[row.action.kind] = seen.get(row.action.kind, 0) + 1
        seq.report("success")
    assert seen["buffer"] and seen["install"], seen


def near_tie_decision() -> Decision:
    """A buffer choice between two parts with equal expected positions that are not interchangeable (x < a,
    y < b): estimated (exact attempts marked as failing there), it stops on the near tie."""
    plan = make_plan([{"id": p} for p in ("x", "a", "y", "b", "z")], {"a": ["x"], "b": ["y"]})
    policy = Opportunistic(budget=10.0, seed=3)
    for band in range(3):
        policy.readings.slow[("buffer", band)] = 100.0   # exact attempts have been failing: estimate at once
    seq = Sequencer(OrderEngine(plan), policy, warm_up=0)
    return seq.decide(["a", "b"])


def test_a_near_tie_states_one_thing():
    decision = near_tie_decision()
    assert not decision.exact and decision.close and decision.confidence < 0.999
    text = decision_view(decision)["explain"]
    assert text.count("sure") == 1 and "exact rule's choice" not in text, text
    assert text.splitlines()[-1].endswith("a near tie: at least 99.9% sure that no other candidate is better by "
                                          "more than 1% of the steps remaining"), text
    assert decision.to_dict()["close"] is True
    again = Decision.recorded(decision.to_dict())          # as the service replays it from its log
    assert again.close and again.explain() == decision.explain()


def test_an_estimate_that_is_no_near_tie_states_its_probability_of_being_the_exact_rules_choice():
    d = Decision(Action("buffer", "a"), "buffer the visible part needed earliest", exact=False, method="mcmc",
                 estimates=(Estimate("a", "position", 2.0, 0.1), Estimate("b", "position", 3.0, 0.1)),
                 confidence=0.93, seconds=0.047)
    assert d.explain().splitlines()[-1] == ("  estimated by mcmc within the decision budget (47 ms): "
                                            "93.0% sure this is the exact rule's choice")
    assert "near tie" not in d.explain() and d.to_dict()["close"] is False
    sure = Decision(d.action, d.rule, exact=False, method="mcmc", confidence=0.99996)
    assert sure.certainty() == "over 99.9% sure this is the exact rule's choice"   # never "100.0%" of an estimate


def test_a_near_tie_recorded_by_an_earlier_version_is_read_as_one():
    old = {"action": {"kind": "buffer", "part": "a", "source": None}, "rule": "buffer",
           "note": "estimated on strategy 's1' alone; stopped early: with probability >= 0.999 no other candidate is "
                   "better than this one by more than 1% (of its share of options, or of the steps remaining for "
                   "positions)",
           "exact": False, "method": "mcmc", "estimates": [{"part": "a", "kind": "share", "value": 0.5, "se": 0.01}],
           "confidence": 0.93, "seconds": 0.05}
    d = Decision.recorded(old)
    assert d.close and d.note == "estimated on strategy 's1' alone"
    assert d.explain().count("sure") == 1 and "of its share of completions" in d.explain()


def test_a_runs_totals_are_what_was_done():
    """Random looks and outcomes (failures, defects, shakes) on the gearbox, each counted as it is reported;
    the totals the service gives a complete run are those counts."""
    plan = load_plan("example:gearbox")
    for seed in range(6):
        rng = random.Random(seed)
        seq = Sequencer(plan, buffer_capacity=rng.choice([None, 1, 2]))
        counted = {"looks": 0, "motions": 0, "buffer_moves": 0, "shakes": 0, "failed": 0}
        peak = 0
        while not seq.finished and not seq.state.is_complete:
            in_bin = [p for p, k in seq.state.in_bin.items() for _ in range(k)]
            look = rng.sample(in_bin, min(len(in_bin), rng.randint(0, 3)))
            action = seq.decide(look).action
            counted["looks"] += 1
            outcome = "success"
            if action.kind == "shake":
                counted["shakes"] += 1
            else:
                counted["motions"] += 1
                counted["buffer_moves"] += action.kind == "buffer"
                outcome = rng.choices(["success", "failed", "defective"], [8, 1, 1])[0]
                counted["failed"] += outcome == "failed"
            seq.report(outcome)
            peak = max(peak, len(seq.state.buffer))
        totals = run_totals(seq, plan)
        assert totals == counted | {"installed": 10, "buffer_peak": peak, "defects": seq.state.defects,
                                    "time": float(counted["motions"] + counted["shakes"])}, seed
