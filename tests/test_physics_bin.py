"""The physical bin (MuJoCo): occlusion by rays, picking, shaking, seeds, every policy, its bounds; and the cell
model's cycle time in seconds, for every bin."""

from __future__ import annotations

import copy
import json
import random

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from opportune import load_plan
from opportune.cli import app
from opportune.formats.loader import plan_from_dict
from opportune.planning.plan import MAX_DIMENSION, MIN_DIMENSION, PlanError
from opportune.study.simulate import ALL_STRATEGIES, StudyConfig, StudyError, run_study
from opportune.worlds import CellModel, make_world
from opportune.worlds import physics
from opportune.worlds.physics import RAY_GRID, PhysicsBin, PhysicsError

GEARBOX = load_plan("example:gearbox")
UNITS = list(GEARBOX.part_ids)


def heap(seed: int, **kwargs) -> PhysicsBin:
    world = PhysicsBin(visible=2, **kwargs)
    world.reset(UNITS, random.Random(seed))
    return world


def brute_force_exposure(world: PhysicsBin) -> dict[int, float]:
    """Each unit's exposure by a loop over its rays, each tested against every geom of the model
    (mju_rayGeom, the nearest hit wins): independent of mj_multiRay's batch and its pruning."""
    m, d = world.model, world.data
    camera = np.array(world.camera)
    out = {}
    for unit in world.units_in_bin():
        own = world.geom_of(unit)
        meets = first = 0
        for vec in world.rays(unit):
            hits = []
            for g in range(m.ngeom):
                if not m.geom_contype[g] and g != own and m.geom_bodyid[g] != 0:
                    continue   # a picked part, parked far away: no ray reaches it anyway
                dist = mujoco.mju_rayGeom(d.geom_xpos[g], d.geom_xmat[g], m.geom_size[g], camera, vec.copy(),
                                          int(m.geom_type[g]))
                if dist >= 0:
                    hits.append((dist, g))
            if any(g == own for _, g in hits):
                meets += 1
                first += min(hits)[1] == own
        out[unit] = first / max(1, meets)
    return out


@pytest.mark.parametrize("seed", [0, 3])
def test_visibility_equals_a_brute_force_ray_count(seed):
    world = heap(seed)
    for _ in range(2):   # the settled heap, then after a pick
        batched = world.exposure()
        assert batched == brute_force_exposure(world)
        assert all(0 <= e <= 1 for e in batched.values())
        assert any(e < 1 for e in batched.values()), "a heap where nothing hides anything tests nothing"
        assert set(world.look()) <= {UNITS[u] for u, e in batched.items() if e >= physics.VISIBLE_FRACTION}
        world.take(world.look()[0])


def test_a_part_with_another_lying_on_it_is_never_pickable():
    # a heap built on purpose: the cover flat on the floor, the case flat on top of it, a third part apart
    world = PhysicsBin(visible=3)
    world.reset(["co", "ca", "st"], random.Random(0))
    world.place({0: (0, 0, 0.011, 1, 0, 0, 0), 1: (0.004, 0, 0.032, 1, 0, 0, 0), 2: (0.05, 0.03, 0.011, 1, 0, 0, 0)})
    assert world.covered() == {0}
    assert "co" not in world.look() and set(world.look()) == {"ca", "st"}
    world.take("ca")   # nothing lies on the cover now
    assert world.covered() == set() and "co" in world.look()


@pytest.mark.parametrize("seed", [1, 2])
def test_pickable_parts_hold_nothing_up(seed):
    """Independently, by physics: lifting a pickable part away lets no other part drop."""
    world = heap(seed)
    m = world.model
    covered = world.covered()
    assert covered, "a heap where nothing lies on anything tests nothing"
    for unit in world.units_in_bin():
        if unit in covered:
            continue
        d = copy.copy(world.data)
        others = [u for u in world.units_in_bin() if u != unit]
        before = {u: float(d.geom_xpos[world.geom_of(u)][2]) for u in others}
        address = m.jnt_qposadr[m.body(f"u{unit}").jntadr[0]]
        d.qpos[address:address + 3] = (10.0, 10.0, 1.0)
        m_copy = copy.copy(m)
        g = world.geom_of(unit)
        m_copy.geom_contype[g] = m_copy.geom_conaffinity[g] = 0
        mujoco.mj_step(m_copy, d, nstep=60)
        mujoco.mj_forward(m_copy, d)
        dropped = {UNITS[u]: round(before[u] - float(d.geom_xpos[world.geom_of(u)][2]), 4) for u in others}
        assert max(dropped.values()) < 0.004, f"{UNITS[unit]} held up {dropped}"


def test_shaking_changes_what_is_visible():
    world = heap(0)
    before = world.look()
    exposure = world.exposure()
    world.shake()
    assert world.look() != before
    assert world.exposure() != exposure
    assert len(world) == len(UNITS)   # a shake keeps every part in the bin


def test_the_same_seed_gives_the_same_trial():
    config = StudyConfig(GEARBOX, strategies=("paper", "buffer"), trials=4, bin="physics", seed=7)
    one = run_study(config, workers=1)
    physics._HEAPS.clear()   # the heaps dropped again, not taken from the cache, in other chunks
    two = run_study(config, workers=1, chunk_size=1)
    for s in config.strategies:
        assert [t.row() for t in one.trials[s]] == [t.row() for t in two.trials[s]]
    other = run_study(StudyConfig(GEARBOX, strategies=("buffer",), trials=4, bin="physics", seed=8), workers=1)
    assert [t.row()[2:] for t in other.trials["buffer"]] != [t.row()[2:] for t in one.trials["buffer"]]
    # the heap, looks and shakes of one seed, on a world of their own
    a, b = heap(5), heap(5)
    for world in (a, b):
        world.shake()
    assert a.look() == b.look() and np.array_equal(a.data.qpos, b.data.qpos)


def test_every_policy_completes_on_the_physical_bin():
    strategies = tuple(s for s in ALL_STRATEGIES if s != "optimal")
    config = StudyConfig(GEARBOX, strategies=strategies, trials=2, bin="physics", training_runs=3, seed=1)
    result = run_study(config, workers=1)
    for s in strategies:
        assert len(result.trials[s]) == 2
        assert all(t.complete and t.motions >= len(UNITS) for t in result.trials[s]), s
        assert all(t.cycle_seconds > 0 for t in result.trials[s])
    with pytest.raises(StudyError, match="'optimal' is defined"):
        StudyConfig(GEARBOX, strategies=("optimal",), bin="physics").validate()


def test_the_bounds_are_checked_before_a_model_is_built(monkeypatch):
    def no_model(*args, **kwargs):
        raise AssertionError("a model was built")

    monkeypatch.setattr(physics, "_model_xml", no_model)
    many = plan_from_dict({"name": "many", "parts": [{"id": "screw", "quantity": physics.MAX_BIN_UNITS + 1}]})
    with pytest.raises(StudyError, match=f"at most {physics.MAX_BIN_UNITS} parts"):
        StudyConfig(many, strategies=("paper",), bin="physics").validate()
    big = plan_from_dict({"name": "big", "parts": [{"id": "plate", "geometry": {"box": [0.3, 0.3, 0.2]}}]})
    with pytest.raises(StudyError, match="cannot lie flat in a bin"):
        StudyConfig(big, strategies=("paper",), bin="physics").validate()
    for geometry in ({"box": [0.01, 0.2, 0.01]}, {"cylinder": [0.005, 0.3]}):   # a rod longer than the bin
        rod = plan_from_dict({"name": "rod", "parts": [{"id": "rod", "geometry": geometry}]})
        with pytest.raises(StudyError, match="cannot lie flat in a bin"):
            StudyConfig(rod, strategies=("paper",), bin="physics").validate()
    fits = plan_from_dict({"name": "fits", "parts": [{"id": "bar", "geometry": {"box": [0.15, 0.01, 0.11]}}]})
    StudyConfig(fits, strategies=("paper",), bin="physics").validate()   # on its side: 0.15 × 0.11
    full = plan_from_dict({"name": "full", "parts": [{"id": "block", "quantity": 30,
                                                       "geometry": {"box": [0.05, 0.05, 0.05]}}]})
    with pytest.raises(StudyError, match="volume"):
        StudyConfig(full, strategies=("paper",), bin="physics").validate()
    for settings, message in (({"settle_steps": physics.MAX_SETTLE_STEPS + 1}, "settle_steps"),
                              ({"bin_size": (0.16, 0.12, 5.0)}, "bin's inside")):
        with pytest.raises(PhysicsError, match=message):
            PhysicsBin(2, **settings)


def test_geometry_in_plan_files_is_checked_with_a_clear_message():
    plan = plan_from_dict({"parts": [{"id": "shaft", "geometry": {"cylinder": [0.01, 0.12]}}, "key"]})
    assert plan.part("shaft").geometry == ("cylinder", (0.01, 0.12)) and plan.part("key").geometry is None
    assert plan_from_dict(plan.to_dict()) == plan and plan_from_dict(plan.to_dict()).part("shaft") == plan.part("shaft")
    for geometry, says in (({"cylinder": [0.01, 0.9]}, "above 0.5 m"), ({"box": [0.01, 0.02]}, "too few dimensions"),
                           ({"sphere": [0.01]}, "not a shape"), ({"box": [0.001, 0.02, 0.02]}, "below 0.005 m")):
        with pytest.raises(PlanError) as refused:
            plan_from_dict({"parts": [{"id": "p", "geometry": geometry}]})
        assert says in str(refused.value) and "geometry: {box: [x, y, z]}" in str(refused.value)


@settings(max_examples=40, deadline=None)
@given(shape=st.sampled_from(["box", "cylinder"]), dims=st.lists(st.floats(0.001, 0.8), min_size=3, max_size=3))
def test_a_geometry_is_accepted_exactly_within_its_bounds(shape, dims):
    dims = dims[:3 if shape == "box" else 2]
    within = all(MIN_DIMENSION <= d <= MAX_DIMENSION for d in dims)
    try:
        plan = plan_from_dict({"parts": [{"id": "p", "geometry": {shape: dims}}]})
    except PlanError as refused:
        assert not within and "geometry" in str(refused)
    else:
        assert within and plan.part("p").geometry == (shape, tuple(dims))


def test_simulate_runs_the_physical_bin_from_the_command_line(tmp_path):
    result = CliRunner().invoke(app, ["simulate", "example:gearbox", "--bin", "physics", "--trials", "2",
                                      "--strategies", "paper,buffer", "--workers", "1", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["bin"] == "physics" and doc["cell"] == CellModel().to_dict()
    assert doc["strategies"]["buffer"]["cycle_seconds"]["mean"] > doc["strategies"]["buffer"]["time"]["mean"]
    plan = tmp_path / "many.yaml"
    plan.write_text("parts: [{id: screw, quantity: 500}]\n")
    refused = CliRunner().invoke(app, ["simulate", str(plan), "--bin", "physics", "--trials", "1"])
    assert refused.exit_code == 1 and "at most 100 parts" in refused.output and "Traceback" not in refused.output


# ---------------------------------------------------------------- the cell model: seconds, for every bin


@pytest.mark.parametrize("bin_model", ["uniform", "pile", "conveyor"])
def test_seconds_are_the_cell_model_applied_to_the_trial(bin_model):
    """Recomputed from the trial's counts: every buffered part is installed from the buffer once."""
    cell = CellModel(speed=0.8, install=1.5, camera=0.25, shake=4.0)
    config = StudyConfig(GEARBOX, strategies=("paper", "shake", "kitting"), trials=50, bin=bin_model,
                         cell=cell)
    result = run_study(config, workers=1)
    for s, trials in result.trials.items():
        for t in trials:
            installs = len(UNITS)
            expected = ((installs - t.buffer_moves) * cell.install_seconds("ca", "bin")
                        + t.buffer_moves * (cell.buffer_seconds("ca") + cell.install_seconds("ca", "buffer"))
                        + t.shakes * cell.shake + t.looks * cell.camera)
            assert t.cycle_seconds == pytest.approx(expected), (s, t)


def test_cell_settings_are_recorded_read_and_checked():
    cell = CellModel(parts={"co": {"install": 6.0}})
    config = StudyConfig(GEARBOX, strategies=("paper",), trials=5, cell=cell)
    assert StudyConfig.from_settings(GEARBOX, config.settings()).cell == cell
    old = {k: v for k, v in config.settings().items() if k != "cell"}   # recorded before seconds existed
    assert StudyConfig.from_settings(GEARBOX, old).cell == CellModel()
    for bad in ({"speed": 0}, {"camera": -1}, {"parts": {"nope": {"pick": 1}}}, {"parts": {"co": {"lift": 1}}},
                {"warp": 1}):
        with pytest.raises(StudyError):
            StudyConfig.from_settings(GEARBOX, {**config.settings(), "cell": {**cell.to_dict(), **bad}})
    slow = run_study(config, workers=1).trials["paper"]
    fast = run_study(StudyConfig(GEARBOX, strategies=("paper",), trials=5), workers=1).trials["paper"]
    assert [t.cycle_seconds - f.cycle_seconds for t, f in zip(slow, fast)] == pytest.approx([4.0] * 5)   # co installed once


def test_a_plan_cell_section_gives_the_command_line_its_seconds(tmp_path):
    plan = tmp_path / "cell.yaml"
    plan.write_text("parts: [a, b]\nrequires: {b: [a]}\nsimulation: {cell: {camera: 0, pick: 0, install: 1, "
                    "speed: 1, bin_fixture: 0.5, parts: {b: {install: 3}}}}\n")
    result = CliRunner().invoke(app, ["simulate", str(plan), "--strategies", "pallet", "--trials", "3", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["strategies"]["pallet"]["cycle_seconds"]["mean"] == pytest.approx(2 * 1.0 + 1 + 3)
    plan.write_text("parts: [a]\nsimulation: {cell: {speed: fast}}\n")
    refused = CliRunner().invoke(app, ["simulate", str(plan), "--trials", "1"])
    assert refused.exit_code != 0 and "speed" in refused.output and "Traceback" not in refused.output


def test_a_dask_cluster_gives_the_same_physical_trials():
    from distributed import LocalCluster

    config = StudyConfig(GEARBOX, strategies=("paper",), trials=4, bin="physics", seed=3)
    local = run_study(config, workers=1)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1") as cluster:
        remote = run_study(config, dask_address=cluster.scheduler_address, chunk_size=2)
    assert [t.row() for t in local.trials["paper"]] == [t.row() for t in remote.trials["paper"]]


def test_the_other_bins_never_load_mujoco():
    """`make demo` installs no extra: a study in an abstract bin must not import MuJoCo (nor numpy for it)."""
    import subprocess
    import sys

    code = ("import sys; from opportune import load_plan; from opportune.study.simulate import StudyConfig, run_study; "
            "run_study(StudyConfig(load_plan('example:gearbox'), strategies=('paper',), trials=5, bin='pile'), "
            "workers=1); print('mujoco' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr
