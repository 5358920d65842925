"""What a user imports from the top-level package, and what the package ships."""

from __future__ import annotations

from pathlib import Path

import opportune


def test_the_main_concepts_import_from_the_package():
    from opportune.engine.schedule import NotAdmissible, OrderEngine, Schedule
    from opportune.sequencer import Sequencer

    assert opportune.Schedule is Schedule
    assert opportune.Sequencer is Sequencer
    assert opportune.OrderEngine is OrderEngine
    assert opportune.NotAdmissible is NotAdmissible
    assert set(opportune.__all__) <= set(dir(opportune))
    plan = opportune.make_plan(["a", "b", "c"], {"c": ["a", "b"]})
    assert opportune.Schedule(plan).count() == 2
    assert opportune.Sequencer(plan).decide(("a", "c")).action.part == "a"


def test_the_package_says_it_is_typed_and_carries_its_licence_files():
    root = Path(opportune.__file__).parent
    assert (root / "py.typed").exists()
    repo = root.parent.parent
    if (repo / "pyproject.toml").exists():          # a source checkout
        for name in ("LICENSE", "CITATION.cff", "CHANGELOG.md"):
            assert (repo / name).stat().st_size > 0


def test_examples_ship_in_the_package_and_load_by_name():
    import json

    from typer.testing import CliRunner

    from opportune import datasets
    from opportune.cli import app
    from opportune.formats.looks import read_looks

    names = [name for name, _, _ in datasets.examples()]
    assert {"gearbox", "gearbox-table1", "gearbox-overconstrained"} <= set(names) and names == sorted(names)
    assert datasets.example_path("gearbox").parent.parent.name == "datasets"   # inside the package
    plan = opportune.load_plan("example:gearbox")
    assert plan.name == "gearbox" and len(plan.parts) == 10
    assert len(read_looks("example:gearbox-table1")) > 5
    runner = CliRunner()
    out = runner.invoke(app, ["replay", "example:gearbox", "example:gearbox-table1", "--json"])
    assert out.exit_code == 0, out.output
    listed = json.loads(runner.invoke(app, ["examples", "--json"]).output)
    assert {"example:gearbox", "example:gearbox-table1", "salbp:KILBRID"} <= {r["name"] for r in listed}
    out = runner.invoke(app, ["count", "example:nope"])
    assert out.exit_code == 1 and "no example named 'nope'" in out.output and "Traceback" not in out.output


def test_version():
    from typer.testing import CliRunner

    from opportune.cli import app

    out = CliRunner().invoke(app, ["--version"])
    assert out.exit_code == 0 and out.output.strip() == f"opportune {opportune.__version__}"


def test_a_plan_from_standard_input():
    import subprocess
    import sys

    from opportune.datasets import example_path, salbp_path

    for source, expected in ((example_path("gearbox"), "336 admissible sequences"),
                             (salbp_path("MITCHELL"), "1449624 admissible sequences")):
        out = subprocess.run([sys.executable, "-m", "opportune.cli", "count", "-"], input=source.read_bytes(),
                             capture_output=True, timeout=120)
        assert out.returncode == 0, out.stderr
        assert expected in out.stdout.decode()
    out = subprocess.run([sys.executable, "-m", "opportune.cli", "check", "-"], input=b"parts: [a, a]\n",
                         capture_output=True, timeout=120)
    assert out.returncode == 1 and b"<stdin>" in out.stdout + out.stderr and b"Traceback" not in out.stderr
