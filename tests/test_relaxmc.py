"""Adaptive relaxation Monte Carlo (engine/relaxmc.py, src/native/relax.cpp): exact pieces, uniform
draws, honest intervals, budgets that stop cleanly.  Every random case is seeded."""

from __future__ import annotations

import itertools
import math
import os
import random
import subprocess
import sys
from collections import Counter as Tally

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune.engine import relaxmc
from opportune.engine.count import Counter
from opportune.engine.deadline import Deadline
from opportune.engine.estimate import estimate_count
from opportune.engine.poset import Poset, bits

core = relaxmc._native()
needs_core = pytest.mark.skipif(core is None, reason="the compiled core is not built")


def random_poset(n: int, density: float, rng: random.Random) -> Poset:
    perm = list(range(n))
    rng.shuffle(perm)
    pairs = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < density]
    return Poset.from_pairs(n, pairs)


def preds(p: Poset) -> list[list[int]]:
    return [list(bits(p.below[v])) for v in range(p.n)]


def brute(p: Poset, elements: list[int]) -> int:
    """Linear extensions of the subposet on ``elements``, by trying every permutation."""
    return sum(all(not p.less(b, a) for i, a in enumerate(perm) for b in perm[i + 1:])
               for perm in itertools.permutations(elements))


def contains(r: relaxmc.RelaxEstimate, true: int, slack: float = 1e-9) -> bool:
    lg = math.log10(true)
    return r.log10_low - slack <= lg <= r.log10_high + slack


# ------------------------------------------------------------------------------ exact parts

@needs_core
def test_whole_order_as_one_piece_is_exact():
    rng = random.Random(1)
    for n, density in [(2, 0.5), (9, 0.2), (16, 0.15), (24, 0.1), (30, 0.12), (40, 0.1)]:
        p = random_poset(n, density, rng)
        relax = core.ArmcRelaxation(n, preds(p), [list(range(n))])
        status, log_r = relax.count(-1.0, -1)
        assert status == 0 and relax.cross_pairs() == 0
        assert log_r == pytest.approx(math.log(Counter(p).count()), rel=1e-12, abs=1e-12)
        r = relaxmc.estimate(p, seconds=30.0)
        assert r.status == "exact" and r.k == n and contains(r, Counter(p).count())


@needs_core
def test_piece_counts_equal_brute_force():
    """e(R) = n! ∏ e(P_i) / n_i!, every e(P_i) against all permutations of the piece."""
    rng = random.Random(2)
    for case in range(12):
        n = rng.randint(6, 14)
        p = random_poset(n, rng.choice([0.15, 0.3, 0.5]), rng)
        order = list(range(n))
        rng.shuffle(order)
        cuts = sorted(rng.sample(range(1, n), min(n - 1, rng.randint(1, 3))))
        pieces = [order[a:b] for a, b in zip([0] + cuts, cuts + [n]) if b > a]
        pieces = [pc for pc in pieces if len(pc) <= 7] + [x for pc in pieces if len(pc) > 7 for x in [pc[:7], pc[7:]]]
        pieces = [pc for pc in pieces if pc]
        relax = core.ArmcRelaxation(n, preds(p), pieces)
        status, log_r = relax.count(-1.0, -1)
        want = math.lgamma(n + 1) + sum(math.log(brute(p, pc)) - math.lgamma(len(pc) + 1) for pc in pieces)
        assert status == 0 and log_r == pytest.approx(want, rel=1e-12), case
        # the cover pairs between pieces are what a draw checks: none iff nothing is relaxed
        between = sum(1 for a, b in p.cover_pairs() if not any(a in pc and b in pc for pc in pieces))
        assert relax.cross_pairs() == between


@needs_core
def test_partition_is_a_partition_and_counts_its_pairs():
    rng = random.Random(3)
    p = random_poset(90, 4 / 89, rng)
    for k in (10, 20, 33):
        pieces, inside, tries = core.armc_partition(p.n, preds(p), k, 20, 7, -1.0)
        assert tries == 20
        assert sorted(x for pc in pieces for x in pc) == list(range(p.n))
        assert all(1 <= len(pc) <= k for pc in pieces)
        assert inside == sum(p.comparable(a, b) for pc in pieces for a, b in itertools.combinations(pc, 2))
        # better than a random cut into the same sizes (the swaps only ever add pairs)
        order = list(range(p.n))
        rng.shuffle(order)
        rand = sum(p.comparable(a, b) for i in range(0, p.n, k) for a, b in itertools.combinations(order[i:i + k], 2))
        assert inside > rand
    assert core.armc_partition(p.n, preds(p), 20, 5, 11, -1.0) == core.armc_partition(p.n, preds(p), 20, 5, 11, -1.0)


@needs_core
def test_bad_input_is_a_value_error():
    p = Poset.from_pairs(3, [(0, 1), (1, 2)])
    with pytest.raises(ValueError):
        core.ArmcRelaxation(3, preds(p), [[0, 1]])                      # 2 is in no piece
    with pytest.raises(ValueError):
        core.ArmcRelaxation(3, preds(p), [[0, 1], [1, 2]])              # 1 twice
    with pytest.raises(ValueError):
        core.ArmcRelaxation(3, [[], [0], [1]], [[0, 1, 2]])              # not transitively closed
    with pytest.raises(ValueError):
        core.armc_partition(3, preds(p), 65, 1, 0, -1.0)


# ------------------------------------------------------------------------------ the draws

@needs_core
def test_relaxation_draws_are_uniform():
    """Chi-square over every linear extension of a small relaxation (2 · 3 · C(7, 3) = 210 of them)."""
    from scipy.stats import chisquare

    p = Poset.from_pairs(7, [(0, 1), (2, 3), (2, 4), (5, 6), (0, 5)])
    pieces = [[0, 1, 2], [3, 4, 5, 6]]       # (0, 5) is dropped, (2, 3) and (2, 4) too
    relax = core.ArmcRelaxation(7, preds(p), pieces)
    status, log_r = relax.count(-1.0, -1)
    allowed = [perm for perm in itertools.permutations(range(7))
               if all(perm.index(a) < perm.index(b) for a, b in [(0, 1), (5, 6)])]
    assert status == 0 and round(math.exp(log_r)) == len(allowed) == 1260
    tally = Tally(tuple(relax.extension(seed)) for seed in range(63000))
    assert set(tally) <= set(allowed) and len(tally) == len(allowed)
    stat, pvalue = chisquare([tally[a] for a in allowed])
    assert pvalue > 1e-3, (stat, pvalue)
    # the hits are the linear extensions of the order: p = e(P) / e(R)
    draws = sum(tally.values())
    hits = sum(c for a, c in tally.items() if all(a.index(x) < a.index(y) for x, y in p.cover_pairs()))
    e_p = Counter(p).count()
    assert abs(hits / draws - e_p / 1260) < 4 * math.sqrt(e_p / 1260 / draws)


@needs_core
def test_hit_counts_match_the_true_proportion():
    """sample()'s early rejection gives the same proportion as whole draws: e(P) / e(R)."""
    rng = random.Random(4)
    p = random_poset(18, 0.15, rng)
    pieces = [list(range(9)), list(range(9, 18))]
    relax = core.ArmcRelaxation(18, preds(p), pieces)
    _, log_r = relax.count(-1.0, -1)
    prop = Counter(p).count() / math.exp(log_r)
    status, draws, hits, placed = relax.sample(200_000, 10**9, -1.0, 5)
    assert status == 1 and draws == 200_000 and placed < 18 * draws
    assert abs(hits / draws - prop) < 4 * math.sqrt(prop * (1 - prop) / draws)
    assert relax.sample(10**9, 100, -1.0, 5)[:3] == (0, relax.sample(10**9, 100, -1.0, 5)[1], 100)


# ------------------------------------------------------------------------------ the intervals

def test_clopper_pearson_against_scipy():
    from scipy.stats import beta

    for h, n in [(0, 10), (1, 10), (7, 40), (50, 100), (99, 100), (1615, 10**6), (40, 10**7)]:
        lo, hi = relaxmc.clopper_pearson(h, n)
        assert lo == pytest.approx(beta.ppf(0.025, h, n - h + 1) if h else 0.0, rel=1e-8)
        assert hi == pytest.approx(beta.ppf(0.975, h + 1, n - h) if h < n else 1.0, rel=1e-8)
    lo, hi = relaxmc.clopper_pearson(30, 60, 0.99)
    assert lo < relaxmc.clopper_pearson(30, 60)[0] < 0.5 < relaxmc.clopper_pearson(30, 60)[1] < hi


def test_target_hits_give_the_width_asked_for():
    for eps in (0.05, 0.1, 0.3):
        h = relaxmc.target_hits(eps)
        for p in (1e-6, 0.01, 0.3):
            n = round(h / p)
            lo, hi = relaxmc.clopper_pearson(h, n)
            assert max(hi * n / h - 1, 1 - lo * n / h) <= eps + 1e-6
        n = round((h - 1) / 1e-6)                      # one hit fewer: wider than asked (the fewest)
        lo, hi = relaxmc.clopper_pearson(h - 1, n)
        assert max(hi * n / (h - 1) - 1, 1 - lo * n / (h - 1)) > eps


@needs_core
def test_coverage_on_orders_with_known_counts():
    """200 estimates (10 orders × 20 seeds, pieces of 5 or 6 so that draws often miss) at ±20 %: the
    stated 95% interval holds the exact count in at least 90% of them.  Stops on hits: deterministic."""
    rng = random.Random(6)
    orders = [random_poset(rng.randint(14, 20), rng.choice([0.12, 0.2]), rng) for _ in range(10)]
    truth = [Counter(p).count() for p in orders]
    covered = 0
    for case in range(200):
        p, true = orders[case % 10], truth[case % 10]
        r = relaxmc.estimate(p, rel_error=0.2, seed=case, k=5 + case % 2)
        assert r.status == "hits" and r.hits == relaxmc.target_hits(0.2) and r.rel_error <= 0.2 + 1e-9
        covered += contains(r, true)
    assert covered >= 180, covered


@needs_core
@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(4, 16), density=st.sampled_from([0.1, 0.25, 0.4]), seed=st.integers(0, 2**32),
       k=st.integers(2, 6))
def test_interval_property(n, density, seed, k):
    """On any small order: the estimate lies in its interval, below the relaxation's count, and the
    99.9% interval holds the exact count (derandomized: the same examples every run)."""
    p = random_poset(n, density, random.Random(seed))
    true = Counter(p).count()
    r = relaxmc.estimate(p, rel_error=0.3, confidence=0.999, seed=seed, k=k)
    assert r.status in ("hits", "exact")
    assert r.log10_low <= r.log10 <= r.log10_high <= r.log10_relaxed + 1e-9
    assert contains(r, true), (r, true)


@needs_core
def test_deterministic_for_a_seed():
    p = random_poset(30, 0.1, random.Random(8))
    a = relaxmc.estimate(p, rel_error=0.1, seed=3, k=10)
    b = relaxmc.estimate(p, rel_error=0.1, seed=3, k=10)
    c = relaxmc.estimate(p, rel_error=0.1, seed=4, k=10)
    assert a == b and a.status == "hits" and c != a


@needs_core
def test_adaptive_choice_is_deterministic_without_a_clock():
    """Without a deadline the choice of k rests on counted work only: the same seed, the same answer."""
    p = random_poset(70, 3 / 69, random.Random(12))
    a = relaxmc.estimate(p, rel_error=0.1, seed=5)
    b = relaxmc.estimate(p, rel_error=0.1, seed=5)
    assert a == b and a.status == "hits" and relaxmc.K_START <= a.k <= relaxmc.K_MAX


@needs_core
def test_whole_false_skips_the_one_piece_count():
    """An order of at most 64 elements is first counted as one piece (exact, in doubles) unless
    ``whole=False``: then it is estimated from pieces of at most 60 elements, its interval holding the count."""
    p = random_poset(40, 0.1, random.Random(21))
    true = Counter(p).count()
    whole = relaxmc.estimate(p, rel_error=0.1, seed=2)
    assert whole.status == "exact" and whole.k == 40 and contains(whole, true)
    parts = relaxmc.estimate(p, rel_error=0.1, seed=2, whole=False)
    assert parts.k < 40 and parts.status == "hits" and parts.draws > 0 and contains(parts, true)


@needs_core
def test_draws_go_on_from_where_they_stopped():
    """A run stopped by its cap on draws and resumed is the run made in one go: the same draws, hits and
    interval (draw i has its own stream, whichever call makes it); a resumed run of another order is refused."""
    p = random_poset(50, 0.05, random.Random(31))
    whole = relaxmc.estimate(p, rel_error=0.01, seed=4, k=20, max_draws=6000)
    first = relaxmc.estimate(p, rel_error=0.01, seed=4, k=20, max_draws=2500)
    assert first.status == "draws" and first.draws == 2500 and first.run is not None
    again = relaxmc.estimate(p, rel_error=0.01, seed=4, k=20, max_draws=6000, resume=first)
    assert (again.draws, again.hits, again.status) == (whole.draws, whole.hits, whole.status)
    assert again == whole and again.draws > first.draws
    with pytest.raises(ValueError, match="50 elements"):
        relaxmc.estimate(random_poset(30, 0.1, random.Random(1)), rel_error=0.1, resume=first)


@needs_core
def test_draws_in_turns_are_the_draws_one_after_another():
    """Eight draws advance in turns, and the outcomes count in the order of the draws: a run of d draws is
    the first d draws of a longer run (so the stop on the target of hits is the one of drawing one by one)."""
    p = random_poset(40, 0.08, random.Random(5))
    relax = core.ArmcRelaxation(40, preds(p), core.armc_partition(40, preds(p), 10, 5, 7, -1.0)[0])
    assert relax.count(-1.0, -1)[0] == 0
    long = relax.sample(4000, 10**9, -1.0, 99)
    for d in (1, 7, 8, 9, 1000):
        short = relax.sample(d, 10**9, -1.0, 99)
        assert short[1] == d and short[2] <= long[2]
    # draws 0..d-1 then d..: the same hits as 0..4000 in one call
    a = relax.sample(1234, 10**9, -1.0, 99)
    b = relax.sample(4000 - 1234, 10**9, -1.0, 99, 1234)
    assert a[2] + b[2] == long[2] and a[3] + b[3] == long[3]
    # stopping on hits: the first draw that reaches the target, as one by one
    h = relax.sample(10**9, 5, -1.0, 99)
    assert h[0] == 0 and h[2] == 5
    assert relax.sample(h[1] - 1, 10**9, -1.0, 99)[2] == 4


@needs_core
def test_any_number_of_threads_makes_the_same_counts_and_draws():
    """Draws are shared out to threads in blocks and their outcomes merged in the order of the draws: the
    stops on hits and on draws fall on the same draw, with the same hits and elements placed, for 1-4
    threads, from any first draw; pieces counted by threads give the same counts; and so the whole
    estimate is the same."""
    p = random_poset(60, 0.06, random.Random(17))
    relax = core.ArmcRelaxation(60, preds(p), core.armc_partition(60, preds(p), 15, 5, 3, -1.0)[0])
    assert relax.count(-1.0, -1)[0] == 0
    for args in [(5000, 10**9, -1.0, 11, 0),          # a cap on draws, not a multiple of a block
                 (10**9, 40, -1.0, 11, 0),            # a target of hits
                 (10**9, 40, -1.0, 11, 3333),         # from a later draw
                 (1, 10**9, -1.0, 2, 0), (0, 5, -1.0, 2, 0)]:
        answers = {relax.sample(*args, threads=t) for t in (1, 2, 3, 4)}
        assert len(answers) == 1, (args, answers)
    hits = relax.sample(10**9, 40, -1.0, 11, threads=1)
    assert hits[0] == 0 and hits[2] == 40 and relax.sample(hits[1] - 1, 10**9, -1.0, 11, threads=3)[2] == 39
    # the pieces counted by threads: the same counts, summed in the order of the pieces
    counts = set()
    for t in (1, 2, 3, 8):
        fresh = core.ArmcRelaxation(60, preds(p), core.armc_partition(60, preds(p), 15, 5, 3, -1.0)[0])
        counts.add((fresh.count(-1.0, -1, t), fresh.entries()))
    assert counts == {(relax.count(-1.0, -1), relax.entries())}
    for t in (1, 3):            # a cap or a clock passed stops every thread, with its status
        fresh = core.ArmcRelaxation(60, preds(p), core.armc_partition(60, preds(p), 15, 5, 3, -1.0)[0])
        assert fresh.count(-1.0, 1024, t)[0] == 1 and fresh.count(0.0, -1, t)[0] in (0, 2)
        with pytest.raises(ValueError, match="threads"):
            fresh.count(-1.0, -1, 0)
    one = relaxmc.estimate(p, rel_error=0.1, seed=6, k=15)
    assert one.status == "hits" and relaxmc.estimate(p, rel_error=0.1, seed=6, k=15, threads=3) == one
    for bad in (0, relaxmc.MAX_THREADS + 1):
        with pytest.raises(ValueError, match="threads"):
            relaxmc.estimate(p, rel_error=0.1, threads=bad)
        with pytest.raises(ValueError, match="threads"):
            relax.sample(10, 10, -1.0, 1, 0, threads=bad)


@needs_core
def test_count_share_bounds_the_time_spent_on_relaxations_that_never_hit():
    """ARC111 cut into pieces of 20-30 elements: no pilot draw hits, so the estimate is hopeless; the
    relaxations' counts stop within ``count_share`` of the time (CPU time, with a margin for the last
    count's pilot), not half of it as by default."""
    from conftest import CpuTime
    from opportune.datasets import salbp_path
    from opportune.formats.salbp import read_in2

    g = read_in2(salbp_path("ARC111"))
    p = Poset.from_pairs(g.n, [(a - 1, b - 1) for a, b in g.pairs])
    with CpuTime() as cpu:
        r = relaxmc.estimate(p, rel_error=0.05, deadline=Deadline.after(8.0), count_share=0.02, hopeless=20)
    assert r.status in ("hopeless", "none") and r.draws == 0
    # CPU time: the share is of the deadline's wall time, which CPU time never exceeds, loaded or not
    assert cpu.seconds < 0.02 * 8.0 + 0.5, cpu.seconds


# ------------------------------------------------------------------------------ budgets

@needs_core
def test_no_time_returns_at_once_with_a_status():
    for p in (random_poset(40, 0.1, random.Random(9)), random_poset(100, 0.05, random.Random(9))):
        r = relaxmc.estimate(p, deadline=Deadline.after(0.0))
        assert r.status == "none" and r.draws == 0 and math.isnan(r.log10)
        assert r.rel_error == math.inf
    relax = core.ArmcRelaxation(3, [[], [0], []], [[0, 1, 2]])
    assert relax.sample(10, 10, 0.0, 1) == (-1, 0, 0, 0)              # not counted yet: a status
    assert relax.count(0.0, -1)[0] in (0, 2)


@needs_core
def test_memory_cap_stops_cleanly_and_resumes():
    p = random_poset(40, 0.06, random.Random(10))
    relax = core.ArmcRelaxation(p.n, preds(p), [list(range(p.n))])
    status, log_r = relax.count(-1.0, 64 * 1024)
    assert status == 1 and math.isnan(log_r) and 0 < relax.bytes() <= 64 * 1024
    status, log_r = relax.count(-1.0, -1)                              # goes on from what it stored
    assert status == 0 and log_r == pytest.approx(math.log(Counter(p).count()), rel=1e-12)
    r = relaxmc.estimate(p, max_bytes=4096, seed=1)
    assert r.status == "none" and r.bytes == 0


# ------------------------------------------------------------------------------ in estimate_count

@needs_core
def test_estimate_count_uses_it_where_the_exact_attempt_fails():
    p = random_poset(34, 0.08, random.Random(11))
    true = Counter(p).count()
    e = estimate_count(p, exact_memo=200, time_limit=20, seed=1)
    assert e.method == "armc" and e.rel_error < 1e-6
    assert e.value == pytest.approx(true, rel=1e-9)
    assert e.log10_low <= math.log10(true) + 1e-9 and math.log10(true) - 1e-9 <= e.log10_high


@needs_core
def test_count_result_takes_the_relaxation_estimate_when_the_exact_count_does_not_fit(monkeypatch):
    """``Schedule.count_result`` (what ``opportune count`` runs): with a memo budget too small for the
    exact count, relaxation Monte Carlo runs while the exact count still could finish, and the answer
    is an estimate at least as narrow as its interval (the later runs' if narrower), which holds the
    true count."""
    from opportune import make_plan
    from opportune.engine import OrderEngine, Schedule

    p = random_poset(50, 3 / 49, random.Random(5))       # a random sparse order: no hub, no cut
    true = Counter(p, max_memo=None).count()
    ids = [f"t{i}" for i in range(p.n)]
    plan = make_plan(ids, {ids[b]: [ids[a] for a in bits(p.below[b])] for b in range(p.n)}, name="sparse")
    import opportune.engine.estimate as estimate_module

    made = []
    original = estimate_module.relaxation_estimate

    def spy(*args, **kwargs):
        made.append(original(*args, **kwargs))
        return made[-1]

    monkeypatch.setattr(estimate_module, "relaxation_estimate", spy)
    r = Schedule(OrderEngine(plan, max_memo=300, time_limit=1.0)).count_result(time_limit=6.0, rel_error=0.05)
    assert len(made) == 1 and made[0] is not None and made[0].method == "armc"
    assert not r.exact and r.method in ("armc", "smc")
    assert r.rel_error <= made[0].rel_error <= 0.05
    if r.method == "armc":
        assert made[0].log10_low - 1e-9 <= r.log10_low <= r.log10_high <= made[0].log10_high + 1e-9
    assert r.log10_low <= math.log10(true) <= r.log10_high


def test_pure_python_still_estimates():
    code = ("import random; from opportune.engine import relaxmc; from opportune.engine.poset import Poset;"
            "from opportune.engine.estimate import estimate_count;"
            "p = Poset.from_pairs(30, [(i, i + 3) for i in range(27)]);"
            "e = estimate_count(p, exact_memo=10, time_limit=2, seed=1);"
            "print(relaxmc.estimate(p), e.method != 'armc', e.log10_low <= e.log10_high)")
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "OPPORTUNE_PURE_PYTHON": "1"})
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["None", "True", "True"]
