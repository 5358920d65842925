"""The command line as a user meets it: exit codes, messages, JSON, no tracebacks."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from conftest import GEARBOX, run_cli
from opportune.cli import app

runner = CliRunner()
run = run_cli


def test_check_gearbox_summary():
    r = run("check", GEARBOX)
    assert r.exit_code == 0
    assert "gearbox" in r.output and "valid" in r.output
    assert "parts: 10" in r.output
    assert "14 constraints declared, 14 minimal" in r.output
    assert "ca -> ba" in r.output


def test_check_json():
    r = run("check", GEARBOX, "--json")
    doc = json.loads(r.output)
    assert doc["valid"] is True and doc["parts"] == 10
    assert ["ca", "ba"] in doc["strategies"][0]["minimal"]
    assert doc["strategies"][0]["implied"] > doc["strategies"][0]["declared"]


def test_check_bad_plan_lists_every_problem(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("parts: [ca, ba, rl]\nrequires:\n  ba: [ca, rl]\n  rl: [ba]\n  xx: [ca]\n")
    r = run("check", bad)
    assert r.exit_code == 1
    assert "unknown part 'xx'" in r.output
    assert f"{bad}:5" in r.output
    r = run("check", bad, "--json")
    assert r.exit_code == 1
    doc = json.loads(r.output)
    assert doc["valid"] is False
    assert {p["code"] for p in doc["problems"]} == {"unknown-part", "cycle"}


def test_check_cycle_message(tmp_path):
    bad = tmp_path / "cyc.yaml"
    bad.write_text("parts: [ca, ba, rl]\nrequires:\n  ba: [ca, rl]\n  rl: [ba]\n")
    r = run("check", bad)
    assert r.exit_code == 1 and "ba -> rl -> ba" in r.output


def test_check_missing_file(tmp_path):
    r = run("check", tmp_path / "none.yaml")
    assert r.exit_code == 1 and "no such file" in r.output


def test_count_gearbox():
    r = run("count", GEARBOX)
    assert r.exit_code == 0 and "336 admissible sequences" in r.output
    doc = json.loads(run("count", GEARBOX, "--json").output)
    assert doc["sequences"] == "336" and doc["exact"] is True
    assert doc["plan"] == "gearbox" and doc["parts"] == 10 and doc["strategies"] == 1
    assert abs(doc["log10"] - 2.526339) < 1e-5


def test_count_invalid_plan_exits_1(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("parts: [a]\nrequires: {a: [a]}\n")
    r = run("count", bad)
    assert r.exit_code == 1 and "requires itself" in r.output


def test_count_salbp(salbp):
    doc = json.loads(run("count", salbp / "MERTENS.IN2", "--json").output)
    assert doc["parts"] == 7 and int(doc["sequences"]) > 0


def test_graph_dot_to_stdout():
    r = run("graph", GEARBOX, "--format", "dot")
    assert r.exit_code == 0
    assert "ca -> ba" in r.output and "co -> st" in r.output
    assert "ca -> rl" not in r.output  # only the minimal constraints are drawn


def test_graph_svg(tmp_path):
    assert shutil.which("dot"), "graphviz 'dot' must be installed (make test installs it)"
    out = tmp_path / "g.svg"
    r = run("graph", GEARBOX, "-o", out)
    assert r.exit_code == 0 and out.read_text().lstrip().startswith("<?xml")
    png = tmp_path / "g.png"
    assert run("graph", GEARBOX, "-o", png).exit_code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_graph_without_dot_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))  # no dot on this PATH
    r = run("graph", GEARBOX, "-o", tmp_path / "g.svg")
    assert r.exit_code == 1
    assert "apt-get install graphviz" in r.output
    assert len([ln for ln in r.output.splitlines() if ln.strip()]) == 1


def test_graph_bad_format():
    r = run("graph", GEARBOX, "--format", "gif")
    assert r.exit_code == 2 and "unknown format" in r.output


def test_schema_command_prints_the_published_schema():
    doc = json.loads(run("schema").output)
    assert doc["title"] == "opportune plan" and "parts" in doc["required"]


# ---------------------------------------------------------------- start-up (issue 11)

# Packages the command line must not load unless a command needs them (the service, plotting,
# distributed runs, drawing); benchmarks/bench_startup.py has the times.
SERVICE_AND_EXTRAS = ("matplotlib", "fastapi", "sqlalchemy", "uvicorn", "starlette", "dask", "distributed", "graphviz")
# ... nor these, before a command has a plan to read (unless typer itself loads them).
PLAN_MACHINERY = ("jsonschema", "yaml", "pydantic", "rich", "opportune.engine", "opportune.formats")


def loaded_by(*argv: str, code: str | None = None) -> set[str]:
    """The modules in ``sys.modules`` of a fresh interpreter after ``code``, or after running
    ``opportune ARGV...`` (exit included) in it."""
    if code is None:
        code = ("import sys\nfrom opportune.cli import main\nsys.argv = ['opportune', *%r]\n"
                "try:\n    main()\nexcept SystemExit:\n    pass\n" % (argv,))
    code += "\nimport sys; print('\\nMODULES', ' '.join(sorted(sys.modules)))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          cwd=GEARBOX.parent.parent)
    line = proc.stdout.rstrip().splitlines()[-1]
    assert line.startswith("MODULES "), proc.stdout + proc.stderr
    return set(line.split()[1:])


def heavy_beyond_typer(mods: set[str]) -> set[str]:
    """The heavy packages in ``mods`` that ``import typer`` alone does not load."""
    typer_mods = loaded_by(code="import typer")
    return {m for m in (*SERVICE_AND_EXTRAS, *PLAN_MACHINERY) if m in mods and m not in typer_mods}


def test_importing_the_cli_loads_no_heavy_package():
    assert heavy_beyond_typer(loaded_by(code="import opportune.cli")) == set()


def test_help_loads_no_plan_machinery():
    # typer (0.29) builds a pydantic adapter for any parameter whose value is not a bool: the main
    # group's absent --help flag is False, not None (cli._Group), so help never needs pydantic
    assert heavy_beyond_typer(loaded_by("count", "--help")) == set()
    assert heavy_beyond_typer(loaded_by("--help")) == set()


def test_count_loads_only_what_it_needs():
    mods = loaded_by("count", "salbp:KILBRID")
    assert "opportune.engine.schedule" in mods  # it did count
    assert {m for m in (*SERVICE_AND_EXTRAS, "yaml") if m in mods} == set()
    mods = loaded_by("count", "examples/gearbox.yaml")
    assert "yaml" in mods and {m for m in SERVICE_AND_EXTRAS if m in mods} == set()


def test_replay_with_a_decision_budget_says_how_each_decision_was_reached(tmp_path):
    """Replay within a budget: every decision carries `exact` (and, when estimated, its method,
    estimates and confidence); with the default (no budget) the reasons are exact and reproducible."""
    looks = tmp_path / "k.looks"
    looks.write_text("1 2\n3 4\n5 6\n")
    timed = json.loads(run("replay", "salbp:KILBRID", looks, "--json", "--explain", "--decision-budget", "0.05").stdout)
    assert timed and all("exact" in row["reasons"] for row in timed)
    for row in timed:
        if not row["reasons"]["exact"]:
            assert row["reasons"]["estimates"] and 0 <= row["reasons"]["confidence"] <= 1
    a = run("replay", "salbp:KILBRID", looks, "--json", "--explain").stdout
    assert a == run("replay", "salbp:KILBRID", looks, "--json", "--explain").stdout
    assert all(row["reasons"]["exact"] is True for row in json.loads(a))


def test_simulate_rejects_a_budget_that_is_not_positive():
    result = runner.invoke(app, ["simulate", str(GEARBOX), "--decision-budget", "0", "--trials", "5"])
    assert result.exit_code != 0 and "decision-budget" in (result.stdout + (result.stderr or ""))


@pytest.mark.parametrize("rel_error,words,absent", [
    (0.1, "±10.00% at 95% confidence", "order of magnitude"),
    (5.6, "only the order of magnitude is known: at most 6.6e+65", "±"),
])
def test_count_states_a_wide_estimate_as_an_order_of_magnitude(monkeypatch, rel_error, words, absent):
    """An interval of ±100% or more bounds nothing from below: the command says what is known instead."""
    from opportune.engine.schedule import CountResult, Schedule

    monkeypatch.setattr(Schedule, "count_result", lambda self, **kw: CountResult(
        1e65, exact=False, rel_error=rel_error, confidence=0.95, method="smc"))
    result = runner.invoke(app, ["count", str(GEARBOX)])
    assert result.exit_code == 0, result.output
    assert words in result.output and absent not in result.output


@pytest.mark.parametrize("log10,rel_error,words", [
    (403.2017, 0.2, "about 1.5911e+403 admissible sequences (log10 403.202)"),
    (403.2017, 5.6, "at most 1.1e+404"),
    (396.5, math.inf, "its runs disagree too much to bound it"),
    (float("nan"), math.inf, "not counted"),
])
def test_count_states_an_estimate_past_a_float_by_its_logarithm(monkeypatch, log10, rel_error, words):
    """A plan of a few hundred steps has more than 1.8e308 sequences: the estimate is stated from its
    logarithm (never "inf" or "nan"), in the text and in the JSON."""
    from opportune.engine.schedule import CountResult, Schedule

    monkeypatch.setattr(Schedule, "count_result", lambda self, **kw: CountResult(
        math.inf, exact=False, rel_error=rel_error, confidence=0.95, method="smc", log10_value=log10))
    result = runner.invoke(app, ["count", str(GEARBOX)])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert words in text and "inf" not in text.replace("information", "")
    doc = json.loads(runner.invoke(app, ["count", str(GEARBOX), "--json"]).stdout)
    assert doc["rel_error"] == (None if math.isinf(rel_error) else rel_error)
    assert doc["log10"] == (None if math.isnan(log10) else round(log10, 6))


def test_count_after_an_unknown_part_answers_in_json_when_asked():
    result = runner.invoke(app, ["count", str(GEARBOX), "--after", "zz", "--json"])
    assert result.exit_code == 1
    doc = json.loads(result.stdout)
    assert "unknown part 'zz'" in doc["error"]["message"]


def test_graph_dpi_and_part_names(tmp_path):
    import struct

    small, large = tmp_path / "small.png", tmp_path / "large.png"
    assert run("graph", GEARBOX, "-o", small, "--dpi", "72").exit_code == 0
    assert run("graph", GEARBOX, "-o", large, "--dpi", "300").exit_code == 0
    w_small = struct.unpack(">I", small.read_bytes()[16:20])[0]
    w_large = struct.unpack(">I", large.read_bytes()[16:20])[0]
    assert 3.5 < w_large / w_small < 4.7          # 300 / 72 = 4.2
    dot = run("graph", GEARBOX, "--names").output
    assert "cover" in dot                          # the cover's name, under its id "co"
    assert "cover" not in run("graph", GEARBOX).output.replace("tooltip=cover", "")


def test_replay_under_another_policy_prints_the_trace_up_to_the_look_that_does_not_fit():
    """Table 1's looks were recorded under the paper's rule; the look-ahead decides otherwise before the
    end, so a later look names parts no longer in the bin: the rows decided so far are printed, then
    the look and why (exit 1); under --json the error carries the trace."""
    looks = GEARBOX.parent / "gearbox-table1.looks"
    r = runner.invoke(app, ["replay", str(GEARBOX), str(looks), "--policy", "lookahead"])
    assert r.exit_code == 1, r.output
    assert "lookahead schedule (stopped after" in r.stdout and "look " in r.stderr and "--policy paper" in r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("│")]
    assert rows, r.stdout
    r = runner.invoke(app, ["replay", str(GEARBOX), str(looks), "--policy", "lookahead", "--json"])
    assert r.exit_code == 1
    doc = json.loads(r.stdout)["error"]
    assert doc["trace"] and all("action" in row for row in doc["trace"])
    assert len(doc["trace"]) < len([line for line in looks.read_text().splitlines() if line.strip()])
