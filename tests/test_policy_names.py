"""One name for the paper's rule: ``paper``.  Its former name ``opportunistic`` is still accepted, with a
deprecation notice (once on standard error for the command line, a DeprecationWarning pointing at the
caller's line in Python, a note in the service's answer: tests/test_service_api.py), and never gives a
second row of the same policy."""

from __future__ import annotations

import json
import warnings

import pytest

from conftest import GEARBOX, run_cli
from opportune import load_plan
from opportune.policies.named import FORMER_NAMES, POLICIES, current_name, current_names, make_policy
from opportune.study.simulate import ALL_STRATEGIES, StudyConfig, run_study


def test_the_former_name_is_not_a_policy_of_its_own():
    assert FORMER_NAMES == {"opportunistic": "paper"}
    assert "paper" in POLICIES and "paper" in ALL_STRATEGIES
    assert not set(FORMER_NAMES) & (set(POLICIES) | set(ALL_STRATEGIES))
    assert make_policy("paper").name == "paper"


def test_python_warns_once_at_the_callers_line():
    with pytest.warns(DeprecationWarning, match="write 'paper'") as caught:
        policy = make_policy("opportunistic")
    assert policy.name == "paper" and len(caught) == 1 and caught[0].filename == __file__
    with pytest.warns(DeprecationWarning) as caught:
        config = StudyConfig(load_plan(GEARBOX), strategies=("opportunistic", "paper", "opportunistic"), trials=5)
    assert config.strategies == ("paper",) and len(caught) == 1 and caught[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert current_names(["paper", "slack", "paper"]) == (("paper", "slack"), [])
        assert current_name("opportunistic", warn=False) == "paper"


def test_a_study_gives_one_row_per_policy_under_either_name():
    with pytest.warns(DeprecationWarning):
        result = run_study(StudyConfig(load_plan(GEARBOX), strategies=("paper", "opportunistic", "random"),
                                       trials=20), workers=1)
    assert list(result.trials) == ["paper", "random"]


def test_a_recorded_study_under_the_former_name_runs_again_quietly():
    config = StudyConfig(load_plan(GEARBOX), strategies=("paper",), trials=5)
    settings = config.settings() | {"strategies": ["opportunistic", "buffer"]}
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # the file's words, not the caller's: no warning
        again = StudyConfig.from_settings(config.plan, settings)
    assert again.strategies == ("paper", "buffer")


def test_the_command_line_gives_one_row_and_one_note():
    out = run_cli("simulate", GEARBOX, "--strategies", "opportunistic,paper,opportunistic", "--trials", "20",
                  "--workers", "1", "--json")
    assert out.exit_code == 0, out.output
    assert list(json.loads(out.stdout)["strategies"]) == ["paper"]
    assert out.stderr.count("'opportunistic' is the former name of the paper's rule: write 'paper'") == 1
    table = run_cli("simulate", GEARBOX, "--strategies", "opportunistic,paper", "--trials", "20", "--workers", "1")
    rows = [line for line in table.stdout.splitlines() if line.startswith("│")]
    names = [r.split("│")[1].strip() for r in rows]
    assert [n for n in names if n] == ["paper"], table.stdout     # a narrow terminal wraps a row's cells
    paper = run_cli("evaluate", GEARBOX, "--policy", "paper", "--json")
    former = run_cli("evaluate", GEARBOX, "--policy", "opportunistic", "--json")
    assert former.exit_code == paper.exit_code == 0, former.output
    assert json.loads(former.stdout)["policy"] == json.loads(paper.stdout)["policy"] == "paper"
    assert json.loads(former.stdout)["expected_time"] == json.loads(paper.stdout)["expected_time"]
    assert former.stderr.count("write 'paper'") == 1 and "write 'paper'" not in paper.stderr
    replay = run_cli("replay", GEARBOX, GEARBOX.parent / "gearbox-table1.looks", "--policy", "opportunistic")
    assert replay.exit_code == 0 and "gearbox: the paper's rule" in replay.stdout
    assert replay.stderr.count("write 'paper'") == 1
