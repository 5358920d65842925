"""Every command that prints a result takes ``--json`` (as the README says), ``graph --json`` gives the layout
the service's dashboard draws, and a plan that cannot be loaded points to ``opportune check`` only when check
says more (its warnings)."""

from __future__ import annotations

import json

import typer.main
from typer.testing import CliRunner

from opportune.cli import app

runner = CliRunner()
# Commands without --json, each for its reason: schema prints JSON already, serve runs the server,
# completion prints a shell script.
WITHOUT_JSON = {"schema", "serve", "completion"}


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def commands(group=None, prefix=""):
    group = group or typer.main.get_command(app)
    for name, sub in group.commands.items():
        if hasattr(sub, "commands"):
            yield from commands(sub, prefix + name + " ")
        else:
            yield prefix + name, sub


def test_every_command_that_prints_a_result_takes_json():
    found = {name: any("--json" in p.opts for p in cmd.params) for name, cmd in commands()}
    assert {name for name, has in found.items() if not has} == WITHOUT_JSON, found


def test_graph_json_is_the_layout_the_service_draws(tmp_path):
    from opportune import datasets
    from opportune.formats.summary import summarize
    from opportune.service.graph import layouts

    out = invoke("graph", "example:gearbox", "--json")
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    plan = datasets.example_path("gearbox")
    from opportune import load_plan

    gear = load_plan(plan)
    assert doc == {"plan": "gearbox", "strategies": json.loads(json.dumps(layouts(gear, summarize(gear))))}
    assert [n["id"] for n in doc["strategies"][0]["nodes"]] == list(gear.part_ids)
    wrote = invoke("graph", "example:gearbox", "-o", tmp_path / "g.dot", "--json")
    assert json.loads(wrote.stdout) == {"plan": "gearbox", "format": "dot", "wrote": str(tmp_path / "g.dot")}
    assert (tmp_path / "g.dot").read_text().startswith("digraph")
    dot = json.loads(invoke("graph", "example:gearbox", "--format", "dot", "--json").stdout)
    assert dot["dot"] == (tmp_path / "g.dot").read_text()
    refused = invoke("graph", tmp_path / "none.yaml", "--json")
    assert refused.exit_code == 1 and json.loads(refused.stdout)["error"]["problems"][0]["code"] == "io"
    converted = invoke("convert", "example:gearbox", tmp_path / "g.json", "--json")
    assert json.loads(converted.stdout) == {"plan": "gearbox", "format": "json", "wrote": str(tmp_path / "g.json")}


def test_check_is_pointed_to_only_when_it_says_more(tmp_path):
    missing = invoke("count", tmp_path / "none.yaml")
    assert missing.exit_code == 1 and "no such file" in missing.output and "opportune check" not in missing.output
    two = tmp_path / "two.yaml"
    two.write_text("parts: [a, b]\nrequires: {a: [c], b: [d]}\n")
    out = invoke("count", two)
    assert out.exit_code == 1 and "2 errors" in out.output and "opportune check" not in out.output
    # an error and a warning: check lists the warning too, so it is pointed to
    warned = tmp_path / "warned.yaml"
    warned.write_text("parts: [a, b]\nrequires: {b: [a, a], a: [x]}\n")
    severities = [p["severity"] for p in json.loads(invoke("check", warned, "--json").stdout)["problems"]]
    assert sorted(severities) == ["error", "warning"]
    out = invoke("count", warned)
    assert out.exit_code == 1 and f"`opportune check {warned}` lists its 1 warning(s) too" in " ".join(out.output.split())
