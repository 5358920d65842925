"""`opportune evaluate --runs N`: the policy's gap estimated from seeded runs by its regrets over the exact
optimum, beside its exact evaluation."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from conftest import GEARBOX
from opportune.limits import MAX_ESTIMATE_RUNS

runner = CliRunner()


def _evaluate(*args: str):
    from opportune.cli import app

    return runner.invoke(app, ["evaluate", str(GEARBOX), "--json", *args])


@pytest.mark.parametrize("bin", ["uniform", "pile"])
def test_the_estimate_is_within_four_standard_errors_of_the_exact_value(bin):
    setting = ["--policy", "paper", "--bin", bin, "--visible", "2", "--buffer-capacity", "1"]
    exact = json.loads(_evaluate(*setting).output)
    got = _evaluate(*setting, "--runs", "400", "--seed", "3")
    assert got.exit_code == 0, got.output
    doc = json.loads(got.output)
    est = doc["estimated"]
    assert exact["estimated"] is None and (est["runs"], est["seed"]) == (400, 3)
    assert doc["optimal"] == pytest.approx(exact["optimal"], rel=1e-12)
    assert exact["expected_time"] > exact["optimal"] and est["looks_off_optimum"] > 0
    assert abs(doc["expected_time"] - exact["expected_time"]) <= 4 * est["expected_time_standard_error"]
    assert doc["expected_time"] == pytest.approx(doc["optimal"] * (1 + est["gap"]), rel=1e-12)
    assert doc["policy_states"] == 0
    assert json.loads(_evaluate(*setting, "--runs", "400", "--seed", "3").output) == doc      # seeded


def test_a_policy_deciding_by_the_optimum_is_not_estimated():
    doc = json.loads(_evaluate("--visible", "2", "--buffer-capacity", "1", "--runs", "50").output)
    assert doc["policy_by_optimum"] and doc["estimated"] is None and doc["expected_time"] == doc["optimal"]


def test_too_few_or_too_many_runs_are_refused_before_any_work():
    one = _evaluate("--policy", "paper", "--runs", "1")
    assert one.exit_code == 2 and "at least 2 runs" in one.output
    many = _evaluate("--policy", "paper", "--runs", str(MAX_ESTIMATE_RUNS + 1))
    assert many.exit_code == 2 and "--runs" in many.output


def test_a_time_limit_passed_stops_the_estimate_saying_where():
    got = _evaluate("--policy", "paper", "--runs", "100", "--time-limit", "0")
    assert got.exit_code != 0
    text = " ".join(got.output.split())
    assert "the estimate of gearbox's gap passed --time-limit 0 s" in text and "give fewer --runs" in text
    assert "Traceback" not in got.output
