"""Certified lower bounds (opportune.study.bounds): below the exact optimum, equal to it with the optimum's
values, the clairvoyant bound without a penalty, the bin's law kept by the exogenous keys."""

from __future__ import annotations

import itertools
import json
import math
import re
import random
import time
from collections import Counter

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import GEARBOX, random_plans, run_cli
from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.policies.optimal import OptimalSolver
from opportune.study.bounds import (DEFECT_SE, PENALTIES, Z95, BoundError, BoundResult, Keys, describe_gaps,
                                    lower_bound, policy_gaps)
from opportune.planning.costs import TimeModel


def lab_plan(seed: int, n: int, strategies: int = 1, density: float = 0.3):
    """A random plan as the policy lab makes them (a random order, each earlier part required with
    chance ``density``), one strategy or several."""
    rng = random.Random(seed)
    ids = [f"p{i}" for i in range(n)]

    def requires():
        order = ids[:]
        rng.shuffle(order)
        return {b: before for j, b in enumerate(order) if (before := [a for a in order[:j] if rng.random() < density])}

    if strategies == 1:
        return make_plan(ids, requires(), name=f"lab-{seed}")
    return make_plan(ids, strategies={f"s{k}": requires() for k in range(strategies)}, name=f"lab-{seed}x{strategies}")


def optimum(plan, visible, capacity, weights=None):
    return OptimalSolver(OrderEngine(plan), visible=visible, capacity=capacity, weights=weights,
                         max_states=2_000_000).value()


CASES = [  # plan, visible, capacity: the gearbox where the default policy is weakest, and the lab's plans
    ("gearbox", 2, None), ("gearbox", 1, 1),
    ("lab-1", 2, None), ("lab-2x2", 1, 2), ("lab-3", 1, None),
]


def case_plan(name):
    if name == "gearbox":
        return load_plan(GEARBOX)
    seed = int(name[4])
    return lab_plan(seed, 8 + seed % 3, strategies=2 if name.endswith("x2") else 1)


@pytest.mark.parametrize("name,visible,capacity", CASES)
def test_the_bound_is_below_the_exact_optimum(name, visible, capacity):
    plan = case_plan(name)
    best = optimum(plan, visible, capacity)
    r = lower_bound(plan, visible=visible, capacity=capacity, trials=100, seed=3, penalty="motions",
                    node_budget=200_000)
    assert r.exact_trials == r.trials
    assert r.high <= best + 0.02, (r.mean, r.half_width, best)
    assert r.mean > 0.8 * best     # a bound that says something


def test_the_clairvoyant_bound_is_below_the_optimum():
    """Without a penalty (the future known, nothing charged for it): below the optimum, where knowing the
    future pays most (1 visible, 1 location)."""
    plan = load_plan(GEARBOX)
    best = optimum(plan, 1, 1)
    none = lower_bound(plan, visible=1, capacity=1, trials=100, seed=3, penalty="none", node_budget=10**6)
    assert none.exact_trials == 100 and none.high <= best


@pytest.mark.parametrize("name,visible,capacity", CASES)
def test_with_the_optimums_values_the_bound_is_the_optimum_on_every_trial(name, visible, capacity):
    """The classical check of an implementation: a perfect value function makes the bound exact."""
    plan = case_plan(name)
    best = optimum(plan, visible, capacity)
    r = lower_bound(plan, visible=visible, capacity=capacity, trials=20, seed=1, penalty="optimal")
    assert r.exact_trials == 20
    assert all(math.isclose(v, best, rel_tol=1e-9, abs_tol=1e-9) for v in r.values)
    assert r.half_width == pytest.approx(0.0, abs=1e-9)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=random_plans(max_parts=4, max_units=5), visible=st.integers(1, 3),
       capacity=st.sampled_from([None, 0, 1, 2]), seed=st.integers(0, 10))
def test_the_optimums_values_give_the_optimum_on_random_plans(plan, visible, capacity, seed):
    """Quantities, several strategies, every buffer: the penalised inner problem's least cost is the optimum."""
    best = optimum(plan, visible, capacity)
    r = lower_bound(plan, visible=visible, capacity=capacity, trials=4, seed=seed, penalty="optimal")
    assert all(math.isclose(v, best, rel_tol=1e-9, abs_tol=1e-9) for v in r.values)


def brute_clairvoyant(plan, visible, capacity, keys: Keys) -> float:
    """The least cost of finishing with every look known: an independent recursion over (look, installed,
    buffer) on part ids (one strategy, one unit per part), the looks cut at a depth no optimum needs."""
    ids = plan.part_ids
    req = {p: set(plan.strategies[0].requires.get(p, ())) for p in ids}
    limit = 3 * len(ids) + 2

    def best(t, installed: frozenset, buffer: frozenset) -> float:
        if len(installed) == len(ids):
            return 0.0
        if t >= limit:
            return math.inf
        in_bin = [p not in installed and p not in buffer for p in ids]
        look = [ids[i] for i in keys.look(t, tuple(int(x) for x in in_bin))]
        out = 1 + best(t + 1, installed, buffer)                      # shake
        for p in set(look) | buffer:
            if req[p] <= installed:
                out = min(out, 1 + best(t + 1, installed | {p}, buffer - {p}))
        if capacity is None or len(buffer) < capacity:
            for p in set(look):
                out = min(out, 1 + best(t + 1, installed, buffer | {p}))
        return out

    from functools import lru_cache
    best = lru_cache(maxsize=None)(best)
    return best(0, frozenset(), frozenset())


@pytest.mark.parametrize("visible,capacity", [(1, None), (1, 1), (2, 0)])
def test_without_a_penalty_each_trial_is_the_clairvoyants_least_cost(visible, capacity):
    plan = lab_plan(7, 5, density=0.5)
    r = lower_bound(plan, visible=visible, capacity=capacity, trials=12, seed=5, penalty="none", node_budget=10**6)
    quantity = [1] * len(plan.parts)
    for trial, value in enumerate(r.values):
        keys = Keys(quantity, None, visible, random.Random(f"bound:5:{trial}"))
        assert value == pytest.approx(brute_clairvoyant(plan, visible, capacity, keys))


def test_a_search_cut_short_stays_below_the_exact_inner_minimum():
    plan = lab_plan(4, 9)
    full = lower_bound(plan, visible=2, trials=10, seed=2, penalty="motions", node_budget=10**6)
    cut = lower_bound(plan, visible=2, trials=10, seed=2, penalty="motions", node_budget=3)
    assert full.exact_trials == 10 and cut.exact_trials < 10
    assert all(c <= f + 1e-9 for c, f in zip(cut.values, full.values))
    assert "bounded at 3 nodes" in cut.method


@pytest.mark.parametrize("weights", [None, {"a": 1.0, "b": 3.0, "c": 0.5}])
def test_the_keys_show_the_bins_looks_with_their_chances(weights):
    """The exogenous keys give each look the chance the bin model gives it (uniform, and weighted: the
    exponential race), here from a bin of a, a, b, c with two visible."""
    plan = make_plan([{"id": "a", "quantity": 2}, "b", "c"], {})
    engine = OrderEngine(plan)
    solver = OptimalSolver(engine, visible=2, weights=weights)
    exact = dict(solver._look_distribution((2, 1, 1)))
    w = None if weights is None else [weights[p] for p in plan.part_ids]
    keys = Keys([2, 1, 1], w, 2, random.Random(11))
    n = 20_000
    seen = Counter(keys.look(t, (2, 1, 1)) for t in range(n))
    assert set(seen) <= set(exact)
    for look, p in exact.items():
        assert abs(seen[look] / n - p) <= 4 * math.sqrt(p * (1 - p) / n) + 1e-9, (look, seen[look] / n, p)


def test_the_same_seed_gives_the_same_bound():
    plan = lab_plan(2, 8)
    a = lower_bound(plan, trials=8, seed=4, penalty="motions")
    b = lower_bound(plan, trials=8, seed=4, penalty="motions")
    c = lower_bound(plan, trials=8, seed=5, penalty="motions")
    assert a.values == b.values and a.values != c.values


def test_weighted_bin_and_costs_stay_below_the_optimum():
    plan = lab_plan(5, 8)
    weights = {p: 1.0 + (i % 3) for i, p in enumerate(plan.part_ids)}
    costs = TimeModel(motion=1.0, shake=2.0, look=0.1)
    best = OptimalSolver(OrderEngine(plan), visible=2, capacity=1, costs=costs, weights=weights).value()
    r = lower_bound(plan, visible=2, capacity=1, bin="weighted", weights=weights, costs=costs, trials=40,
                    penalty="motions", node_budget=100_000)
    assert r.high <= best + 0.02 and r.mean > 0.8 * best


@pytest.mark.parametrize("kwargs,words", [
    ({"bin": "pile"}, "Markov bins"),
    ({"trials": 1}, "from 2"),
    ({"penalty": "perfect"}, "choose from"),
    ({"node_budget": 0}, "node_budget"),
    ({"visible": 0}, "visible"),
    ({"capacity": -1}, "capacity"),
])
def test_a_bad_request_says_what_to_change(kwargs, words):
    with pytest.raises(BoundError, match=words):
        lower_bound(load_plan(GEARBOX), **kwargs)


def test_the_optimums_penalty_on_a_large_plan_is_refused_before_the_work():
    cpu = time.process_time()
    with pytest.raises(BoundError, match="more than .* states"):
        lower_bound(load_plan("salbp:KILBRID"), penalty="optimal", trials=10)
    assert time.process_time() - cpu < 10     # the states are counted, within 2 s, not solved


def test_a_large_plan_gets_a_bound_above_its_motions():
    """KILBRID (45 parts): a few trials within a small budget: above the 45 motions every part needs, below
    the default policy's mean (66.2 ± 0.6 on 200 bins, 2 visible, unlimited buffer)."""
    r = lower_bound(load_plan("salbp:KILBRID"), trials=3, seed=0, node_budget=500)
    assert r.penalty == "motions" and r.exact_trials == 0
    assert 45 < r.mean < 64


def test_simulate_prints_the_bound_beside_the_policies():
    out = run_cli("simulate", GEARBOX, "--strategies", "lookahead,paper", "--trials", "200", "--bound")
    assert out.exit_code == 0, out.output
    text = " ".join(out.output.split())
    assert "lower bound on any online policy's expected time" in text and re.search(r"paper \d+\.\d% above", text)
    # the look-ahead is the optimum here: its mean of 200 trials is below the bound (the optimum itself), and
    # the line calls it below, and noise, not "above" with a minus sign
    assert re.search(r"lookahead \d+\.\d% below", text) and "lookahead below the bound is sampling noise" in text
    assert "-" not in text.split("each policy's mean against it:")[1].split(".")[0]
    doc = json.loads(run_cli("simulate", GEARBOX, "--strategies", "paper", "--trials", "50", "--bound",
                             "--json").output)
    assert doc["bound"]["penalty"] == "optimal" and doc["bound"]["mean"] == pytest.approx(13.5711, abs=1e-4)
    assert doc["bound"]["policies"]["paper"]["gap"] > -0.1


@settings(max_examples=60, deadline=None)
@given(st.floats(5, 20), st.floats(0, 0.5), st.floats(5, 20), st.floats(0.001, 0.5))
def test_each_gap_is_worded_by_its_sign_and_a_mean_below_the_bound_is_explained(bound, bound_half, mean, half):
    """A mean above the bound is called above, one below it below (never "above" with a minus sign), and one
    below it is sampling noise within the 95% intervals, rarer noise up to DEFECT_SE standard errors, a
    defect beyond: each said in words."""
    r = BoundResult(bound, bound_half, 200, "m", "motions", 200, 0, 0.0, bound)
    gaps = policy_gaps(r, {"p": {"mean": mean, "ci95": [mean - half, mean + half]}})
    g = gaps["p"]
    assert g["gap"] == pytest.approx(mean / bound - 1)
    words = describe_gaps(gaps)
    assert ("below" in words.split(";")[0]) == (mean < bound) and ("above" in words.split(";")[0]) == (mean >= bound)
    assert "-" not in words.split("%")[0], words     # the sign is the word, not a minus
    if mean >= bound:
        assert g["below"] is None and "noise" not in words and "defect" not in words
    else:
        z = (bound - mean) / (math.hypot(half, bound_half) / Z95)
        assert g["z"] == pytest.approx(z)
        expected = "noise" if z <= Z95 else "rare" if z <= DEFECT_SE else "defect"
        assert g["below"] == expected
        assert {"noise": "is sampling noise", "rare": "once in 40 studies", "defect": "a defect"}[expected] in words


def test_simulate_offers_every_penalty_of_the_bound():
    """--penalty NAME: each of the bound's penalties from the command line (the README's number is the
    'motions' penalty's), a wrong name or --penalty without --bound refused before the study."""
    for penalty in PENALTIES:
        out = run_cli("simulate", GEARBOX, "--strategies", "paper", "--trials", "20", "--bound", "--penalty", penalty,
                      "--json")
        assert out.exit_code == 0, out.output
        bound = json.loads(out.output)["bound"]
        assert bound["penalty"] == {"auto": "optimal"}.get(penalty, penalty) and bound["trials"] == 20
        assert bound["mean"] <= 13.5711 + 1e-4 + 2 * bound["half_width"]
    wrong = run_cli("simulate", GEARBOX, "--trials", "100000", "--bound", "--penalty", "motion")
    assert wrong.exit_code == 2 and f"choose from {', '.join(PENALTIES)}" in wrong.output
    alone = run_cli("simulate", GEARBOX, "--trials", "100000", "--penalty", "motions")
    assert alone.exit_code == 2 and "give --bound too" in alone.output


def test_the_readme_bound_is_what_its_command_prints():
    """The README quotes the bound its own command line prints (the command, run as written)."""
    import shlex

    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    found = re.search(r"`(opportune simulate [^`]*--bound[^`]*)`\s+prints ([0-9.]+ ± [0-9.]+)", readme)
    assert found, "the README's --bound example: a command in backticks, then 'prints MEAN ± HALF'"
    command, quoted = found.groups()
    out = run_cli(*shlex.split(command)[1:])
    assert out.exit_code == 0, out.output
    assert "lower bound on any online policy's expected time" in out.output
    assert f": {quoted} (95%)" in " ".join(out.output.split()), (quoted, out.output)


def test_simulate_bound_in_the_pile_is_refused_before_the_study():
    out = run_cli("simulate", GEARBOX, "--bin", "pile", "--trials", "100000", "--bound")
    assert out.exit_code == 2 and "--bound is defined for the uniform and weighted bins" in out.output
