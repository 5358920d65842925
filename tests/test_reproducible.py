"""Reproducible results and command-line conventions: the demo twice gives the same files, a recorded
study runs again from its results.json, trials as a DataFrame, several files to check, -h, completion."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import GEARBOX, run_cli
from opportune.cli import app
from opportune.study.simulate import METRICS, StudyConfig, StudyError, run_study

ROOT = Path(__file__).resolve().parents[1]
OPPORTUNE = [sys.executable, "-m", "opportune"]
run = run_cli


def without_timing(doc: dict) -> dict:
    doc = json.loads(json.dumps(doc))
    doc.pop("timing")
    doc["provenance"].pop("command", None)
    return doc


def demo_simulate_command(out: Path) -> list[str]:
    """The `opportune simulate` line of `make demo`, read from the Makefile, writing into ``out``."""
    line = next(line for line in (ROOT / "Makefile").read_text().splitlines() if "opportune simulate" in line)
    args = shlex.split(line.split("/opportune", 1)[1])
    args[args.index("--out") + 1] = str(out)
    return [*OPPORTUNE, *args]


def test_two_runs_of_the_demo_write_the_same_files(tmp_path):
    """`make demo`'s study, twice, with one worker and with two: the same results.json (its timing
    fields aside, kept under "timing"), the same trials.csv and byte-identical figures."""
    a, b = tmp_path / "a", tmp_path / "b"
    for out, workers in ((a, "1"), (b, "2")):
        subprocess.run(demo_simulate_command(out) + ["--workers", workers], cwd=ROOT, check=True,
                       capture_output=True, timeout=300)
    one, two = (json.loads((d / "results.json").read_text()) for d in (a, b))
    assert set(one["timing"]["cpu_seconds"]) == set(one["strategies"])
    assert (one["timing"]["workers"], two["timing"]["workers"]) == (1, 2)
    assert all("seconds" not in s and "solve_seconds" not in s for s in one["strategies"].values())
    assert without_timing(one) == without_timing(two)
    files = sorted(p.name for p in a.iterdir())
    assert files == sorted(p.name for p in b.iterdir())
    assert {"trials.csv", "mean_time.pdf", "mean_time.svg", "time_distribution.png"} <= set(files)
    for name in files:
        if name != "results.json":
            assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_a_recorded_study_runs_again_from_its_results(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert run("simulate", GEARBOX, "--trials", 200, "--seed", 7, "--strategies", "paper,random,buffer",
               "--buffer-capacity", 1, "--shake-cost", 2, "--out", a).exit_code == 0
    assert run("simulate", "--from", a / "results.json", "--out", b).exit_code == 0
    first, again = (json.loads((d / "results.json").read_text()) for d in (a, b))
    assert without_timing(first) == without_timing(again)
    assert (a / "trials.csv").read_bytes() == (b / "trials.csv").read_bytes()
    study = first["provenance"]["study"]
    assert (study["trials"], study["seed"], study["buffer_capacity"], study["costs"]["shake"]) == (200, 7, 1, 2.0)

    # options given on the command line override the recorded ones, and only those
    r = run("simulate", "--from", a / "results.json", "--trials", 50, "--strategies", "random", "--json")
    doc = json.loads(r.output)
    assert doc["trials"] == 50 and list(doc["strategies"]) == ["random"]
    assert (doc["seed"], doc["buffer_capacity"], doc["costs"]["shake"]) == (7, 1, 2.0)
    first_50 = [row for row in (a / "trials.csv").read_text().splitlines() if row.startswith("random,")][:50]
    column = (a / "trials.csv").read_text().splitlines()[0].split(",").index("time")
    times = [float(row.split(",")[column]) for row in first_50]
    assert doc["strategies"]["random"]["time"]["mean"] == pytest.approx(sum(times) / 50)   # the same bins


def test_a_results_file_that_cannot_be_rerun_is_refused_clearly(tmp_path):
    a = tmp_path / "a"
    run("simulate", GEARBOX, "--trials", 20, "--strategies", "random", "--out", a)
    doc = json.loads((a / "results.json").read_text())
    cases = {
        "not json": ("{not json", "not JSON"),
        "no study": (json.dumps({"plan": "gearbox"}), "records no study"),
        "edited plan": (json.dumps({**doc, "provenance": {**doc["provenance"], "plan": {
            **doc["provenance"]["plan"], "parts": doc["provenance"]["plan"]["parts"][:-1]}}}), None),
        "bad setting": (json.dumps({**doc, "provenance": {**doc["provenance"], "study": {
            **doc["provenance"]["study"], "trials": "many"}}}), "'trials' must be a number"),
        "missing setting": (json.dumps({**doc, "provenance": {**doc["provenance"], "study": {
            k: v for k, v in doc["provenance"]["study"].items() if k != "costs"}}}), "lack 'costs'"),
        "nested": ("[" * 100_000 + "]" * 100_000, "nested more than"),
    }
    for name, (text, words) in cases.items():
        path = tmp_path / f"{name}.json"
        path.write_text(text)
        r = run("simulate", "--from", path)
        assert r.exit_code != 0, name
        assert "error:" in r.output, (name, r.output)
        if words:
            assert words in r.output, (name, r.output)
    r = run("simulate", "--from", tmp_path / "missing.json")
    assert r.exit_code != 0 and "cannot read" in r.output
    r = run("simulate", GEARBOX, "--from", a / "results.json")
    assert r.exit_code == 2 and "not both" in r.output
    r = run("simulate", "--json")
    assert r.exit_code == 2 and json.loads(r.output)["error"]["message"].startswith("give a plan file")


def test_study_settings_round_trip_and_refuse_nonsense():
    from opportune import load_plan

    plan = load_plan(GEARBOX)
    config = StudyConfig(plan, strategies=("random", "shake"), trials=30, seed=3, bin="weighted", visible=3,
                         buffer_capacity=2, training_runs=5, decision_budget=0.02)
    again = StudyConfig.from_settings(plan, json.loads(json.dumps(config.settings())))
    assert again == config
    for bad in ({"bin": "sideways"}, {"trials": 0}, {"strategies": ["teleport"]}, {"colour": "red"}):
        with pytest.raises(StudyError):
            StudyConfig.from_settings(plan, {**config.settings(), **bad})


def test_trials_as_a_data_frame_are_the_rows_of_trials_csv(tmp_path):
    pd = pytest.importorskip("pandas", reason="pandas is an optional extra; `make test` installs it")
    from opportune import load_plan
    from opportune.study.report import write_outputs

    result = run_study(StudyConfig(load_plan(GEARBOX), strategies=("paper", "random"), trials=60), workers=1)
    frame = result.to_frame()
    assert list(frame.columns) == ["strategy", "trial", *METRICS, "complete"]
    assert len(frame) == 120
    write_outputs(result, tmp_path)
    csv = pd.read_csv(tmp_path / "trials.csv")
    assert (frame["time"].to_numpy() == csv["time"].to_numpy()).all()
    assert (frame["trial"].to_numpy() == csv["trial"].to_numpy()).all()
    paired = frame.pivot(index="trial", columns="strategy", values="time")
    difference = (paired["random"] - paired["paper"]).mean()
    from opportune.study.report import summary

    assert difference == pytest.approx(summary(result)["strategies"]["random"]["paired"]["mean_difference"])


def test_check_takes_several_files(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("parts: [a, b]\nrequires:\n  a: [b]\n  b: [a]\n")
    r = run("check", GEARBOX, "salbp:MERTENS")
    assert r.exit_code == 0 and "gearbox" in r.output and "MERTENS" in r.output and "2 files: all valid" in r.output
    r = run("check", GEARBOX, bad)
    assert r.exit_code == 1 and "cycle" in r.output and "gearbox" in r.output
    doc = json.loads(run("check", GEARBOX, bad, "--json").output)
    assert doc["valid"] is False and [f["valid"] for f in doc["files"]] == [True, False]
    one = json.loads(run("check", GEARBOX, "--json").output)
    assert one["valid"] is True and one["file"] == str(GEARBOX)   # one file: its document, as before


def test_short_help_everywhere():
    for args in ([], ["count"], ["simulate"], ["serve"]):
        r = run(*args, "-h")
        assert r.exit_code == 0 and "Usage:" in r.output and "Show this message" in r.output, args


def test_every_option_says_what_it_does():
    import typer.main

    group = typer.main.get_command(app)
    for name, command in group.commands.items():
        for param in command.params:
            if param.param_type_name == "option" and param.name != "help":
                assert (param.help or "").strip(), f"opportune {name} {param.opts[0]} has no help text"


def test_shell_completion_scripts_and_answers():
    env = {**os.environ, "COMP_WORDS": "opportune count salbp:KI", "COMP_CWORD": "2",
           "_OPPORTUNE_COMPLETE": "complete_bash"}
    done = subprocess.run(OPPORTUNE, env=env, capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["salbp:KILBRID"], done.stdout + done.stderr
    env.update(COMP_WORDS="opportune si", COMP_CWORD="1")
    assert subprocess.run(OPPORTUNE, env=env, capture_output=True, text=True, timeout=60).stdout.split() == ["simulate"]
    for shell, words in (("bash", "complete -o default -F"), ("zsh", "compdef"), ("fish", "complete --command")):
        r = run("completion", shell)
        assert r.exit_code == 0 and words in r.output and "_OPPORTUNE_COMPLETE" in r.output, shell
    r = run("completion", "tcsh")
    assert r.exit_code == 2 and "bash, zsh, fish, powershell" in r.output



@pytest.mark.parametrize("args, code, words", [
    (["count", "/no/such/plan.yaml"], 1, "not a valid plan"),
    (["count", GEARBOX, "--after", "zz"], 1, "unknown part 'zz'"),
    (["count"], 2, "Missing argument"),
    (["simulate", GEARBOX, "--trials", "0"], 2, "--trials"),
    (["simulate", GEARBOX, "--strategies", "teleport"], 1, "unknown strategy 'teleport'"),
    (["replay", GEARBOX, "/no/such.looks"], 1, "no such file"),
    (["evaluate", GEARBOX, "--bin", "conveyor"], 2, "conveyor"),
    (["check", GEARBOX, "--colour"], 2, "No such option"),
])
def test_under_json_every_error_is_json_on_standard_output(args, code, words):
    done = subprocess.run([*OPPORTUNE, *map(str, args), "--json"], capture_output=True, text=True, timeout=120)
    assert done.returncode == code, done.stdout + done.stderr
    error = json.loads(done.stdout)["error"]
    assert words in error["message"] and error["exit_code"] == code
    assert "Traceback" not in done.stderr
