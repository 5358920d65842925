"""The simulation study: worlds, strategies, the optimum, reproducibility and the report."""

from __future__ import annotations

import json
import math
import random
from collections import Counter as Tally
from itertools import combinations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import GEARBOX, CpuTime, random_plans, salbp_dir
from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.policies.optimal import OptimalSolver
from opportune.study.report import describe, summary, table_rows, write_outputs
from opportune.study.simulate import (STRATEGIES, StrategyUnavailable, StudyConfig, StudyError, TrialRunner, prepare,
                                run_study, run_trial_with_sequencer)
from opportune.worlds import ConveyorBin, PileBin, TimeModel, UniformBin, WeightedBin

GEAR = load_plan(GEARBOX)


def study(plan=GEAR, **kw):
    kw.setdefault("trials", 400)
    return run_study(StudyConfig(plan=plan, **kw), workers=1)


def mean(xs):
    xs = list(xs)
    return sum(xs) / len(xs)


# ---------------------------------------------------------------- worlds


def test_uniform_bin_looks_are_uniform_pairs():
    from scipy.stats import chisquare

    world = UniformBin(2)
    world.reset(list("abcd"), random.Random(1))
    draws = Tally(tuple(sorted(world.look())) for _ in range(6000))
    pairs = [tuple(sorted(p)) for p in combinations("abcd", 2)]
    assert set(draws) == set(pairs)
    assert chisquare([draws[p] for p in pairs]).pvalue > 0.001


def test_weighted_bin_shows_heavy_parts_more():
    world = WeightedBin(1, {"big": 3.0, "small": 1.0})
    world.reset(["big", "small"], random.Random(2))
    n = sum(world.look() == ("big",) for _ in range(8000))
    assert abs(n / 8000 - 0.75) < 0.02
    world = WeightedBin(2, {"a": 5.0})
    world.reset(["a", "b", "c"], random.Random(3))
    assert all(len(set(world.look())) == 2 for _ in range(100))


def test_pile_shows_the_top_and_uncovers_the_next():
    world = PileBin(2)
    world.reset(list("abcde"), random.Random(4))
    stack = list(world.units)
    assert world.look() == tuple(stack[:2])
    world.take(stack[1])
    assert world.look() == (stack[0], stack[2])
    before = list(world.units)
    world.shake()
    assert sorted(world.units) == sorted(before)


def test_conveyor_moves_one_place_per_look_and_parts_go_round():
    world = ConveyorBin(2)
    world.reset(list("abcd"), random.Random(5))
    belt = list(world.units)
    assert world.look() == tuple(belt[:2])
    assert world.look() == tuple(belt[1:3])  # not taken: the belt moved on
    world.take(belt[1])
    assert world.look() == (belt[2], belt[3])
    seen = [world.look() for _ in range(3)]
    assert seen[-1][0] == belt[2] or belt[0] in sum(seen, ())  # the first part came round again


# ---------------------------------------------------------------- strategies against hand-computed values


def test_pallet_costs_exactly_n_motions_and_kitting_2n():
    r = study(strategies=("pallet", "kitting"), trials=200)
    assert {t.motions for t in r.trials["pallet"]} == {10}
    assert {t.shakes for t in r.trials["pallet"]} == {0}
    assert {t.motions for t in r.trials["kitting"]} == {20}
    assert {t.buffer_moves for t in r.trials["kitting"]} == {10}
    assert {t.buffer_peak for t in r.trials["kitting"]} == {10}


def test_kitting_with_quantities_is_two_motions_per_unit():
    plan = make_plan([{"id": "sc", "quantity": 3}, "co", "ba"], {"sc": ["co"], "co": ["ba"]})
    r = study(plan, strategies=("kitting", "pallet"), trials=100)
    assert {t.motions for t in r.trials["kitting"]} == {10}
    assert {t.motions for t in r.trials["pallet"]} == {5}


@pytest.mark.parametrize("k", [1, 2, 3])
def test_shake_expected_shakes_closed_form(k):
    # The next part is visible with probability min(k, r)/r when r units are in the bin: shakes until
    # then are geometric with mean (r - k)/k; summed over r = n .. 1.
    n = 10
    expected = sum((r - k) / k for r in range(k + 1, n + 1))
    r = study(strategies=("shake",), visible=k, trials=3000)
    shakes = [t.shakes for t in r.trials["shake"]]
    d = describe(shakes)
    half = 4 * d["sd"] / math.sqrt(len(shakes))
    assert abs(d["mean"] - expected) < half, (d["mean"], expected)
    assert {t.motions for t in r.trials["shake"]} == {n}


def test_buffer_strategy_buffers_only_when_the_next_part_is_missing():
    r = study(strategies=("buffer",), visible=10, trials=50)  # everything visible: never a need to buffer
    assert {t.buffer_moves for t in r.trials["buffer"]} == {0}
    assert {t.shakes for t in r.trials["buffer"]} == {0}


def test_opportunistic_never_shakes_with_an_unlimited_buffer_in_a_uniform_bin():
    r = study(strategies=("paper",), trials=300)
    assert {t.shakes for t in r.trials["paper"]} == {0}
    assert all(t.motions == 10 + t.buffer_moves for t in r.trials["paper"])


def test_finite_buffer_makes_the_hybrid_shake():
    r = study(strategies=("paper",), buffer_capacity=0, trials=300)
    assert {t.buffer_peak for t in r.trials["paper"]} == {0}
    assert mean(t.shakes for t in r.trials["paper"]) > 0


def test_quantify_learns_the_weighted_order():
    plan = make_plan([{"id": "a", "visibility": 0.2}, {"id": "b", "visibility": 5.0}, "c"])
    cfg = StudyConfig(plan=plan, strategies=("quantify",), bin="weighted", trials=10, training_runs=300)
    prepared = prepare(cfg)
    assert prepared.quantify_rank["b"] < prepared.quantify_rank["c"] < prepared.quantify_rank["a"]
    runner = TrialRunner("quantify", OrderEngine(plan), cfg, prepared)
    assert runner.policy.sequence == ("b", "c", "a")


# ---------------------------------------------------------------- the fast trial loop is the sequencer


@pytest.mark.parametrize("strategy", STRATEGIES)
@pytest.mark.parametrize("bin_model", ["uniform", "weighted", "pile", "conveyor"])
def test_trial_loop_equals_the_full_sequencer(strategy, bin_model):
    if strategy == "optimal" and bin_model not in ("uniform", "weighted"):
        return
    plan = make_plan([{"id": "a", "visibility": 2.0}, "b", "c", {"id": "d", "quantity": 2}, "e"],
                     {"c": ["a"], "d": ["b"], "e": ["c", "d"]})
    cfg = StudyConfig(plan=plan, strategies=(strategy,), bin=bin_model, buffer_capacity=2, trials=30,
                      training_runs=20)
    engine = OrderEngine(plan)
    prepared = prepare(cfg, engine)
    runner = TrialRunner(strategy, engine, cfg, prepared)
    for trial in range(30):
        assert runner.run(trial) == run_trial_with_sequencer(strategy, engine, cfg, prepared, trial)


# ---------------------------------------------------------------- the optimum


def value_iteration(plan, visible, capacity, costs):
    """An independent optimum: Bellman iteration over all states, looks enumerated as unit subsets."""
    engine = OrderEngine(plan)
    ids = plan.part_ids
    solver = OptimalSolver(engine, visible=visible, capacity=capacity, costs=costs)  # only for _moves
    # Enumerate reachable states by search.
    start = solver.start_key()
    states, frontier = {start}, [start]

    def looks(key):
        mask, _, buf = key
        bin_units = []
        for i, p in enumerate(plan.parts):
            installed = sum(1 for u in range(engine.first[i], engine.first[i] + p.quantity) if mask >> u & 1)
            bin_units += [i] * (p.quantity - installed - buf[i])
        k = min(visible, len(bin_units))
        subsets = list(combinations(range(len(bin_units)), k))
        tally = Tally(tuple(sorted(bin_units[j] for j in s)) for s in subsets)
        return [(look, c / len(subsets)) for look, c in tally.items()]

    while frontier:
        key = frontier.pop()
        if key[0] == engine.full:
            continue
        for look, _ in looks(key):
            for _, nxt, _ in solver._moves(key, look):
                if nxt not in states:
                    states.add(nxt)
                    frontier.append(nxt)
    V = {s: 0.0 for s in states}
    for _ in range(5000):
        delta = 0.0
        for s in states:
            if s[0] == engine.full:
                continue
            total = costs.look
            for look, p in looks(s):
                m = min((c + V[n] for c, n, _ in solver._moves(s, look)), default=math.inf)
                total += p * min(m, costs.shake + V[s])
            delta = max(delta, abs(total - V[s]))
            V[s] = total
        if delta < 1e-12:
            break
    return V[start]


@settings(max_examples=25, deadline=None)
@given(random_plans(max_parts=4, max_units=5, max_strategies=2),
       st.integers(1, 3), st.sampled_from([None, 0, 1]), st.sampled_from([0.5, 1.0, 3.0]))
def test_optimum_equals_value_iteration(plan, visible, capacity, shake):
    costs = TimeModel(shake=shake)
    solver = OptimalSolver(OrderEngine(plan), visible=visible, capacity=capacity, costs=costs)
    assert solver.value() == pytest.approx(value_iteration(plan, visible, capacity, costs), abs=1e-7)


def test_optimum_of_a_chain_is_the_shake_closed_form():
    # A chain has one admissible sequence; with no buffer the optimum is exactly `shake`.
    plan = make_plan(list("abcde"), {"b": ["a"], "c": ["b"], "d": ["c"], "e": ["d"]})
    v = OptimalSolver(OrderEngine(plan), visible=2, capacity=0).value()
    assert v == pytest.approx(5 + sum((r - 2) / 2 for r in range(3, 6)))


def test_optimum_refuses_above_the_state_limit():
    cfg = StudyConfig(plan=GEAR, strategies=("optimal",), optimal_states=50, trials=10)
    with pytest.raises(StudyError, match="more than 50 states"):
        prepare(cfg)


def test_no_strategy_beats_the_optimum_beyond_monte_carlo_error():
    r = study(trials=1500, seed=3)
    optimum = r.prepared.optimal_start
    assert 10 < optimum < 20
    for name, trials in r.trials.items():
        if name == "pallet":  # another world: no uncertainty at all
            continue
        d = describe([t.time for t in trials])
        assert d["mean"] + 4 * d["sd"] / math.sqrt(d["n"]) >= optimum, name
    d = describe([t.time for t in r.trials["optimal"]])
    assert abs(d["mean"] - optimum) < 4 * d["sd"] / math.sqrt(d["n"])


def test_gearbox_opportunistic_beats_buffer_kitting_and_shake():
    r = study(strategies=("paper", "buffer", "kitting", "shake", "optimal"), trials=1500)
    doc = summary(r)["strategies"]
    opp = doc["paper"]["time"]
    for other in ("buffer", "kitting", "shake"):
        assert opp["ci95"][1] < doc[other]["time"]["ci95"][0], other
    assert doc["paper"]["ratio_to_optimal"] >= 1 - 0.02


# ---------------------------------------------------------------- reproducibility and scale


def test_same_seed_same_numbers_on_any_number_of_workers():
    cfg = StudyConfig(plan=GEAR, strategies=("paper", "random", "shake"), trials=300, seed=11)
    one = run_study(cfg, workers=1, chunk_size=37)
    two = run_study(cfg, workers=2, chunk_size=50)
    for s in cfg.strategies:
        assert [t.row() for t in one.trials[s]] == [t.row() for t in two.trials[s]]
    other = run_study(StudyConfig(plan=GEAR, strategies=("random",), trials=300, seed=12), workers=1)
    assert [t.row() for t in other.trials["random"]] != [t.row() for t in one.trials["random"]]


def test_dask_local_cluster_gives_the_same_numbers():
    from distributed import Client, LocalCluster

    cfg = StudyConfig(plan=GEAR, strategies=("paper", "quantify", "optimal"), trials=200, seed=5,
                      training_runs=30)
    local = run_study(cfg, workers=1)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1") as cluster:
        remote = run_study(cfg, dask_address=cluster.scheduler_address, chunk_size=40)
    for s in cfg.strategies:
        assert [t.row() for t in local.trials[s]] == [t.row() for t in remote.trials[s]]


def test_interrupt_reports_what_finished():
    cfg = StudyConfig(plan=GEAR, strategies=("paper",), trials=1000)
    calls = []

    def progress(strategy, n):
        calls.append(n)
        if len(calls) == 3:
            raise KeyboardInterrupt

    r = run_study(cfg, workers=1, chunk_size=100, progress=progress)
    assert r.interrupted and len(r.trials["paper"]) == 300


def test_interrupted_before_a_strategy_finished_a_trial_still_reports(tmp_path):
    cfg = StudyConfig(plan=GEAR, strategies=("paper", "shake"), trials=400)

    def progress(strategy, n):
        raise KeyboardInterrupt  # at the first finished chunk: shake has none

    r = run_study(cfg, workers=1, chunk_size=100, progress=progress)
    assert r.interrupted and len(r.trials["paper"]) == 100 and not r.trials["shake"]
    rows = {row[0]: row for row in table_rows(summary(r))}
    assert rows["shake"][1] == "no trial finished" and float(rows["paper"][1].split(" ± ")[0]) > 10
    assert list(rows) == ["paper", "shake"]  # strategies without trials last
    files = {p.name for p in write_outputs(r, tmp_path)}
    assert "mean_time.png" in files
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["strategies"]["shake"]["time"]["n"] == 0
    r.trials["paper"].clear()  # nothing finished at all: the files, without plots
    assert {p.name for p in write_outputs(r, tmp_path / "empty")} == {"results.json", "trials.csv"}


def test_bad_study_configurations():
    with pytest.raises(StudyError, match="unknown strategy 'magic'"):
        StudyConfig(plan=GEAR, strategies=("magic",)).validate()
    with pytest.raises(StudyError, match="'optimal' is defined for the uniform, weighted and pile"):
        StudyConfig(plan=GEAR, strategies=("optimal",), bin="conveyor").validate()


# ---------------------------------------------------------------- report and CLI


def test_describe_matches_numpy():
    import numpy as np

    xs = [random.Random(9).random() * 10 for _ in range(101)]
    d = describe(xs)
    assert d["mean"] == pytest.approx(np.mean(xs))
    assert d["sd"] == pytest.approx(np.std(xs, ddof=1))
    assert d["p5"] == pytest.approx(np.percentile(xs, 5))
    assert d["p95"] == pytest.approx(np.percentile(xs, 95))


def test_outputs_are_written(tmp_path):
    r = study(strategies=("paper", "shake", "optimal"), trials=200)
    files = {p.name for p in write_outputs(r, tmp_path)}
    assert {"results.json", "trials.csv", "time_distribution.png", "time_distribution.svg",
            "mean_time.png", "mean_time.svg"} <= files
    rows = (tmp_path / "trials.csv").read_text().splitlines()
    assert len(rows) == 1 + 3 * 200 and rows[0].startswith("strategy,trial,motions")
    assert (tmp_path / "time_distribution.png").read_bytes()[:4] == b"\x89PNG"


def test_simulate_cli_json_shape(tmp_path):
    from typer.testing import CliRunner

    from opportune.cli import app

    r = CliRunner().invoke(app, ["simulate", str(GEARBOX), "--trials", "300", "--workers", "1", "--json",
                                 "--strategies", "paper,shake,optimal", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    assert doc["plan"] == "gearbox" and doc["bin"] == "uniform" and doc["trials"] == 300 and doc["seed"] == 0
    for name in ("paper", "shake", "optimal"):
        s = doc["strategies"][name]
        for metric in ("motions", "shakes", "time", "buffer_peak"):
            assert set(s[metric]) >= {"mean", "sd", "p5", "p50", "p95", "max", "ci95"}
        assert s["ratio_to_optimal"] > 0.9
    assert doc["strategies"]["optimal"]["expected_time"] == pytest.approx(13.5711, abs=1e-3)
    assert json.loads((tmp_path / "results.json").read_text()) == doc


def test_simulate_cli_errors():
    from typer.testing import CliRunner

    from opportune.cli import app

    r = CliRunner().invoke(app, ["simulate", str(GEARBOX), "--strategies", "optimal", "--bin", "conveyor"])
    assert r.exit_code == 1 and "uniform, weighted and pile" in r.output and "Traceback" not in r.output
    r = CliRunner().invoke(app, ["simulate", str(GEARBOX), "--strategies", "magic"])
    assert r.exit_code == 1 and "unknown strategy 'magic'" in r.output


def test_a_plan_too_large_for_exact_counts_runs_the_strategies_that_need_none():
    """ARC111 (111 tasks): the first look's exact counts take seconds, so with a short limit the
    opportunistic policy is refused up front, with a message; the fixed-sequence strategies still run
    (their sequence needs no count), and on the command line, where no --decision-budget is given, the
    counting policies decide within the sequencer's 50 ms budget instead, and the output says so."""
    from typer.testing import CliRunner

    from opportune.cli import app

    arc = salbp_dir() / "ARC111.IN2"
    plan = load_plan(arc)
    cfg = StudyConfig(plan=plan, strategies=("shake", "paper"), trials=3, count_time_limit=0.3)
    with pytest.raises(StrategyUnavailable, match="'paper' ranks the candidates by exact counts") as info:
        prepare(cfg)
    assert info.value.strategy == "paper" and "--strategies" in str(info.value)
    r = run_study(StudyConfig(plan=plan, strategies=("kitting", "buffer"), trials=3), workers=1)
    assert [t.motions for t in r.trials["kitting"]] == [2 * plan.n_units] * 3
    assert all(t.complete for t in r.trials["buffer"])

    args = ["simulate", str(arc), "--trials", "2", "--workers", "1", "--count-time-limit", "0.3"]
    out = CliRunner().invoke(app, [*args, "--strategies", "paper,kitting", "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    assert {"paper", "kitting"} <= set(doc["strategies"])
    assert "decide within 50 ms per decision" in out.stderr and doc["provenance"]["study"]["decision_budget"] == 0.05
    out = CliRunner().invoke(app, [*args, "--strategies", "kitting,pallet"])
    assert out.exit_code == 0 and "kitting" in out.output
    out = CliRunner().invoke(app, [*args, "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    assert {"paper", "kitting", "buffer", "shake"} <= set(doc["strategies"])
    assert "leaving 'paper' out" not in out.stderr and "decide within 50 ms" in out.stderr


def test_time_limited_counts_give_up_and_restore_the_limits():
    from opportune.engine.count import BudgetExceeded

    engine = OrderEngine(load_plan(salbp_dir() / "ARC111.IN2"))
    assert engine.installable(0, engine.all_strategies) == tuple(
        p for p in engine.plan.part_ids if not engine.plan.strategies[0].requires.get(p))  # without counting
    with CpuTime() as cpu, pytest.raises(BudgetExceeded) as info:
        with engine.time_limited(0.2):
            engine.count(0, engine.all_strategies)
    assert info.value.reason == "time" and cpu.seconds < 5
    assert engine.time_limit is None and engine.counter(engine.all_strategies).time_limit is None


@settings(max_examples=60, deadline=None)
@given(random_plans(max_parts=5, max_units=6, max_strategies=2), st.sampled_from([None, 0, 1, 2]),
       st.integers(0, 2**32))
def test_situations_with_equal_decision_keys_get_equal_decisions(plan, capacity, seed):
    from opportune.engine import Schedule
    from opportune.policies.opportunistic import Opportunistic
    from opportune.sequencer import State

    rng = random.Random(seed)
    engine = OrderEngine(plan)
    policy = Opportunistic()
    key = policy.decision_key(engine, capacity)
    index = {p: i for i, p in enumerate(plan.part_ids)}
    decided: dict = {}
    for _ in range(60):
        s = Schedule(engine)
        for _ in range(rng.randint(0, plan.n_units - 1)):
            s = s.install(rng.choice(s.installable()))
        left = [p for p, n in s.remaining.items() for _ in range(n)]
        rng.shuffle(left)
        nbuf = rng.randint(0, len(left) if capacity is None else min(capacity, len(left)))
        buffer, in_bin = tuple(left[:nbuf]), left[nbuf:]
        look = tuple(sorted(rng.sample(in_bin, min(len(in_bin), rng.randint(0, 3))), key=index.__getitem__))
        action = policy.choose(State(s, buffer=buffer, capacity=capacity), look)
        k = key(s.mask, s.consistent, buffer, look)
        assert decided.setdefault(k, action) == action


def test_opportunistic_is_refused_when_the_first_looks_positions_do_not_fit(monkeypatch):
    """The rule needs expected positions (what to buffer) as well as counts: a plan whose counts fit but
    whose positions do not (ARC111 through its hub) is refused up front, not run for minutes a trial."""
    from opportune.engine.count import BudgetExceeded

    def too_slow(self, *args, **kwargs):
        raise BudgetExceeded("exact count exceeded its time limit", reason="time")

    monkeypatch.setattr(OrderEngine, "position_sums_for", too_slow)
    with pytest.raises(StrategyUnavailable) as info:
        prepare(StudyConfig(plan=GEAR, strategies=("paper",), trials=1, count_time_limit=1.0))
    assert "expected positions" in str(info.value) and "--decision-budget" in str(info.value)


def test_results_carry_their_provenance(tmp_path):
    from opportune import __version__
    from opportune.study.simulate import hash_config

    one = study(strategies=("paper",), trials=50)
    doc = summary(one)["provenance"]
    assert doc["opportune"] == __version__ and doc["schema_version"] >= 1
    assert doc["study_sha256"] == hash_config(one.config) and doc["strategies"] == ["paper"]
    other = study(plan=make_plan(["a", "b"], {"b": ["a"]}), strategies=("paper",), trials=50)
    assert summary(other)["provenance"]["plan_sha256"] != doc["plan_sha256"]
    # the same study on more workers: the same provenance (nothing in it depends on the machine or the run)
    again = run_study(StudyConfig(plan=GEAR, strategies=("paper",), trials=50), workers=2)
    assert summary(again)["provenance"] == doc
    write_outputs(one, tmp_path)
    assert json.loads((tmp_path / "results.json").read_text())["provenance"]["plan_sha256"] == doc["plan_sha256"]


def test_figures_are_paper_ready_and_byte_identical_for_the_same_study(tmp_path):
    """PNG at 300 dpi, SVG with its text as text, PDF; no dates: the same study writes the same bytes."""
    one = study(strategies=("paper", "random", "buffer"), trials=60)
    again = study(strategies=("paper", "random", "buffer"), trials=60)
    a, b = tmp_path / "a", tmp_path / "b"
    write_outputs(one, a)
    write_outputs(again, b)
    for stem in ("time_distribution", "mean_time"):
        for ext in ("png", "svg", "pdf"):
            assert (a / f"{stem}.{ext}").read_bytes() == (b / f"{stem}.{ext}").read_bytes(), f"{stem}.{ext}"
        svg = (a / f"{stem}.svg").read_text()
        assert "<text" in svg and "paper" in svg and "<dc:date>" not in svg
        assert (a / f"{stem}.pdf").read_bytes()[:4] == b"%PDF"
    import struct
    png = (a / "mean_time.png").read_bytes()
    width = struct.unpack(">I", png[16:20])[0]
    assert width == 1050                                      # 3.5 inches (a single column) at 300 dpi
    assert "5th and 95th percentiles" in (a / "time_distribution.svg").read_text()


def test_paired_differences_use_the_same_bins_and_are_tighter():
    """Trial i of every strategy draws the same bin: the difference of two strategies is measured on
    pairs, with an interval much narrower than the two means' (and that contains their difference)."""
    from opportune.study.report import paired_difference

    r = study(strategies=("paper", "random"), trials=1500)
    doc = summary(r)["strategies"]
    paired = doc["random"]["paired"]
    assert paired["with"] == "paper"
    diff = doc["random"]["time"]["mean"] - doc["paper"]["time"]["mean"]
    assert abs(paired["mean_difference"] - diff) < 1e-9 and paired["n"] == 1500
    lo, hi = paired["ci95"]
    assert lo <= diff <= hi
    unpaired = doc["random"]["time"]["ci95"][1] - doc["random"]["time"]["ci95"][0]
    assert hi - lo < unpaired / 2
    assert paired_difference(r.trials["random"][:1], r.trials["paper"]) is None
    assert "paired" not in doc["paper"]
