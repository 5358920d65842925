"""The command line as a user meets it: exit codes, messages, JSON, no tracebacks."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from conftest import GEARBOX
from opportune.cli import app

runner = CliRunner()


def run(*args):
    result = runner.invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result


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
