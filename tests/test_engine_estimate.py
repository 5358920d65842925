"""estimate_count: exact when cheap; otherwise the true count lies within the stated error."""

from __future__ import annotations

import math
import random

import pytest

from opportune.engine.count import Counter
from opportune.engine.estimate import Estimate, _stated_error, _t_quantile, estimate_count
from opportune.engine.poset import Poset
from conftest import salbp_poset

def salbp(name: str) -> Poset:
    return salbp_poset(name)


def random_poset(n: int, density: float, rng: random.Random) -> Poset:
    perm = list(range(n))
    rng.shuffle(perm)
    pairs = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < density]
    return Poset.from_pairs(n, pairs)


def within(est: Estimate, true: int) -> bool:
    return abs(est.value - true) <= est.rel_error * est.value + 1e-9 * true


def test_exact_when_cheap():
    p = Poset.from_pairs(5, [(0, 1), (1, 2), (3, 4)])
    e = estimate_count(p)
    assert (e.value, e.rel_error, e.confidence, e.method, e.exact) == (10.0, 0.0, 1.0, "exact", 10)
    assert e.interval() == (10.0, 10.0)
    e = estimate_count(p, 0b00111)
    assert e.exact == 1


def test_decomposable_sets_are_exact_without_sampling():
    """HESKIA splits into chains and components: no piece is left to sample, even with no exact budget."""
    p = salbp("HESKIA")
    e = estimate_count(p, exact_memo=0, hub=0, tail=0)
    assert e.method == "exact" and e.exact == Counter(p).count()


def test_reuses_a_counter_memo():
    p = salbp("KILBRID")
    c = Counter(p)
    exact = c.count()
    e = estimate_count(p, counter=c, exact_memo=0)
    assert e.method == "exact" and e.exact == exact


@pytest.mark.parametrize("name, particles, tail", [("KILBRID", 64, 10), ("TONGE70", 128, 15)])
def test_salbp_truth_within_stated_error(name, particles, tail):
    """Few particles and a short exact tail force real sampling (and resampling) on graphs with a known count.

    It stops on accuracy (±50% after at least 12 runs), not on the clock: the same runs on a loaded
    machine (12 and 16 runs here, 0.4 s and 1.6 s of CPU); the time limit only stops a broken estimator."""
    p = salbp(name)
    exact = Counter(p).count()
    e = estimate_count(p, exact_memo=0, hub=0, particles=particles, tail=tail, rel_error=0.5, min_runs=12,
                       time_limit=120, seed=1)
    assert e.method == "smc" and e.samples >= 12
    assert e.confidence == 0.95
    assert e.rel_error <= 0.5
    assert within(e, exact), (e, exact)
    assert abs(e.log10_value - math.log10(exact)) < 0.1


def test_random_posets_coverage():
    """The stated 95% interval covers the truth in (nearly) every case; deterministic seeds, and stops
    on accuracy (after 20 runs at least), not on the clock, so the same runs under any load."""
    rng = random.Random(5)
    hits = 0
    cases = 12
    for k in range(cases):
        p = random_poset(rng.randint(10, 22), rng.choice([0.1, 0.2, 0.3]), rng)
        exact = Counter(p).count()
        e = estimate_count(p, exact_memo=0, hub=0, particles=8, tail=2, rel_error=0.3, min_runs=20, time_limit=60,
                           seed=k)
        assert e.method in ("smc", "exact")
        hits += within(e, exact)
    assert hits >= cases - 2


def test_small_population_is_the_exact_programme():
    """While every step has at most ``particles`` distinct sets nothing is sampled: the runs agree exactly."""
    p = random_poset(22, 0.12, random.Random(4))
    exact = Counter(p).count()
    e = estimate_count(p, exact_memo=0, hub=0, particles=100_000, tail=0, rel_error=0.01, time_limit=60, seed=0)
    assert e.method == "smc" and e.rel_error == 0.0
    assert abs(e.value - exact) <= 1e-9 * exact


def test_deterministic_given_seed_when_accuracy_reached():
    p = random_poset(24, 0.15, random.Random(2))
    a = estimate_count(p, exact_memo=0, hub=0, particles=16, tail=4, rel_error=0.2, time_limit=30, seed=3)
    b = estimate_count(p, exact_memo=0, hub=0, particles=16, tail=4, rel_error=0.2, time_limit=30, seed=3)
    assert a == b
    assert a.rel_error <= 0.2 and a.samples >= 20        # no stop on accuracy before min_runs=20 runs


def test_out_of_time_is_stated_honestly():
    """With no time at all, the two runs that any stated error needs still finish, and the error is theirs."""
    p = salbp("KILBRID")
    e = estimate_count(p, exact_memo=0, hub=0, particles=64, tail=5, time_limit=0.0, seed=0)
    assert e.method == "smc" and e.samples == 2 and 0 < e.rel_error < math.inf
    exact = Counter(p).count()
    assert e.rel_error > abs(e.value / exact - 1) or e.rel_error > 0.5    # wide, as two runs must be


@pytest.mark.parametrize("n, density, particles", [(24, 0.15, 3), (26, 0.12, 2)])
def test_repeated_seeds_cover_the_truth(n, density, particles):
    """The stated 95% interval holds the exact count in at least 90% of 80 estimates (8 random orders x
    10 seeds).  Very few particles make the runs vary several-fold and right-skewed; each estimate stops
    on accuracy (±50%: deterministic), after 20-60 runs.  Measured: 80/80 and 79/80; the statement
    before issue 11 (plain t interval, a stop from 4 runs on) covered 67/80 and 66/80."""
    rng = random.Random(7)
    posets = [random_poset(n, density, rng) for _ in range(8)]
    exact = [Counter(p).count() for p in posets]
    hits = 0
    for k in range(80):
        p, true = posets[k % 8], exact[k % 8]
        e = estimate_count(p, exact_memo=0, hub=0, particles=particles, tail=2, rel_error=0.5, time_limit=120,
                           seed=k)
        assert e.method == "smc" and e.samples >= 20 and 0 < e.rel_error <= 0.5
        hits += within(e, true)
    assert hits >= 72, hits


def _plain_t_error(runs: list[float]) -> float:
    """The statement before issue 11: Student's t on the estimates themselves, no margin."""
    n = len(runs)
    mx = max(runs)
    ws = [math.exp(x - mx) for x in runs]
    mean = sum(ws) / n
    sd = math.sqrt(sum((w - mean) ** 2 for w in ws) / (n - 1))
    return _t_quantile(0.975, n - 1) * sd / math.sqrt(n) / mean


def _coverage(stated, draw, n: int, sets: int, seed: int) -> float:
    """Share of ``sets`` samples of ``n`` run logs (``draw(rng)``: the log of an unbiased estimate of 1)
    whose stated interval around their mean holds 1."""
    rng = random.Random(seed)
    hits = 0
    for _ in range(sets):
        runs = [draw(rng) for _ in range(n)]
        mx = max(runs)
        value = math.exp(mx) * sum(math.exp(x - mx) for x in runs) / n
        hits += abs(1 / value - 1) <= stated(runs)
    return hits / sets


@pytest.mark.parametrize("n", [2, 4, 6, 10])
def test_stated_error_covers_skewed_runs(n):
    """Runs whose estimates are right-skewed, as sequential Monte Carlo's are: from 4 runs on, a few runs
    that happen to agree below the truth made the plain t interval miss it in 13-14% of 1,500 samples
    (lognormal, log spread 0.8) and 10-12% (logs skewed 0.7, spread 0.42); the stated error covers it in
    96-98.5% (required: 93%)."""
    sigma = 0.8

    def lognormal(rng):
        return rng.gauss(-sigma * sigma / 2, sigma)

    def skewed(rng):       # normal + exponential logs: E[e^x] = e^(0.045) / 0.7, shifted to 1
        return rng.gauss(0, 0.3) + rng.expovariate(1 / 0.3) - (0.045 - math.log(0.7))

    new = lambda runs: _stated_error(runs, 0.95)
    for draw in (lognormal, skewed):
        assert _coverage(new, draw, n, 1500, seed=n) >= 0.93
    if n >= 4:      # the statement it replaces was too narrow here
        assert _coverage(_plain_t_error, lognormal, n, 1500, seed=n) < 0.9
        assert _coverage(_plain_t_error, skewed, n, 1500, seed=n) < 0.915


def test_stated_error_edge_cases():
    assert _stated_error([], 0.95) == math.inf
    assert _stated_error([3.0], 0.95) == math.inf
    assert _stated_error([3.0, 3.0, 3.0], 0.95) == 0.0
    assert _stated_error([3.0, -math.inf, 2.0], 0.95) == math.inf      # a run that found nothing
    runs = [10.0, 10.2, 9.9, 10.1]
    e = _stated_error(runs, 0.95)
    assert 0 < e < 1
    assert _stated_error(runs[::-1], 0.95) == pytest.approx(e)
    assert _stated_error([x + 1000.0 for x in runs], 0.95) == pytest.approx(e)     # scale-free
    assert _stated_error(runs, 0.99) > e > _stated_error(runs, 0.8)
    assert _stated_error(runs + runs, 0.95) < e                                       # more runs, narrower
    assert _stated_error([10.0, 10.4, 9.8, 10.2], 0.95) > e                           # more spread, wider


def test_t_quantiles():
    for df, t in [(1, 12.706), (2, 4.303), (3, 3.182), (4, 2.776), (10, 2.228), (30, 2.042), (1000, 1.962)]:
        assert abs(_t_quantile(0.975, df) - t) < 2e-3 * t


def test_bad_arguments():
    p = Poset.antichain(3)
    with pytest.raises(ValueError):
        estimate_count(p, 0b1000)
    with pytest.raises(ValueError):
        estimate_count(p, confidence=1.5)
