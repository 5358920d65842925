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
