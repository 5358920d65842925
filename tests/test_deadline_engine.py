"""One deadline through the exact engine: every public entry point stops in time and leaves its memo whole.

Each entry point of the exact side of the engine (counts, position sums, samples, hub counts and
searches, tail distributions, down-set programmes, dominance, relaxation, the compiled core) is
called on random large orders (200 to 3,000 elements, sparse and layered like assembly graphs) with
a short :class:`~opportune.engine.deadline.Deadline`.  It must return, or raise
:class:`~opportune.engine.deadline.BudgetExceeded`, having used at most the deadline plus
:data:`MARGIN` seconds of this process's CPU time (CPU, not wall-clock time, so that the bound
holds on a loaded machine, where the deadline passes while the process waits).  After a stop, the
same counter must still give the brute-force count of a small set of the same order, so a stop
never leaves a wrong or half-stored value in a memo.
"""

from __future__ import annotations

import gc
import random
import time
from itertools import permutations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from opportune.engine import native
from opportune.engine.count import Counter, count_linear_extensions
from opportune.engine.deadline import BudgetExceeded, Deadline
from opportune.engine.dominance import earliest_by_order, most_options_by_order
from opportune.engine.downsets import (
    count_by_downsets,
    count_downsets_bounded,
    position_sums_by_downsets,
    upset_counts,
)
from opportune.engine.hub import (
    HubPath,
    TailCounter,
    hub_candidates,
    hub_count,
    hub_split,
)
from opportune.engine.poset import Poset, bits
from opportune.derive.relax import RelaxRefused, RelaxTimeout, min_feedback_arc_set

#: CPU seconds an entry point may use past its deadline: the longest step between two readings of
#: the clock (a big-integer product or a scan of a 3,000-element set: milliseconds) with room for
#: the Python calls around it.
MARGIN = 0.1

#: Elements of the small set (the top of the order) whose count is checked by brute force after a stop.
TOP = 6


def random_order(n: int, kind: str, seed: int) -> Poset:
    """A random order on ``0..n-1``, numbered in a topological order (pairs go from lower to higher).

    ``sparse``: each element needs 0-2 earlier ones, anywhere (counting is hard: wide, tangled);
    ``layered``: each needs 1-2 of the previous dozen (a layered assembly graph).
    """
    r = random.Random(seed)
    pairs = []
    for i in range(1, n):
        if kind == "layered":
            lo = max(0, i - 12)
            pairs += [(r.randrange(lo, i), i) for _ in range(r.choice((1, 2)))]
        else:
            pairs += [(r.randrange(0, i), i) for _ in range(r.choice((0, 1, 1, 2)))]
    return Poset.from_pairs(n, pairs)


def brute_count(poset: Poset, mask: int) -> int:
    """Linear extensions of ``mask`` by listing every permutation (small sets only)."""
    xs = list(bits(mask))
    return sum(all(not poset.below[x] & mask & ~(sum(1 << y for y in perm[:i]))
                   for i, x in enumerate(perm)) for perm in permutations(xs))


def top(poset: Poset, k: int = TOP) -> int:
    """The ``k`` highest elements: an up-set, as the generator numbers elements topologically."""
    return poset.full & ~((1 << (poset.n - k)) - 1)


def a_hub(poset: Poset) -> int:
    """An element with elements below and above it (the one with most below)."""
    return max((h for h in range(poset.n) if poset.above[h] and poset.below[h]),
               key=lambda h: poset.below[h].bit_count())


# Each entry point: (poset, deadline) -> the Counter whose memo is checked afterwards (or None).
def _count(native_ok):
    def run(p, d):
        c = Counter(p, native=None if native_ok else False)
        run.counter = c
        c.count(deadline=d)
    return run


def _position_sums(p, d):
    c = _position_sums.counter = Counter(p, native=False)
    c.position_sums(deadline=d)


def _expected_positions(p, d):
    c = _expected_positions.counter = Counter(p)
    c.expected_positions(deadline=d)


def _sample(p, d):
    c = _sample.counter = Counter(p, native=False)
    c.sample(random.Random(1), deadline=d)


def _hub_path(p, d):
    hp = HubPath(p, deadline=d)
    _hub_path.counter = hp.counter
    _hub_path.hub = hp
    hp.count(p.full, deadline=d, discover=True)


def _hub_position_sum(p, d):
    hp = HubPath(p, deadline=d)
    _hub_position_sum.counter = hp.counter
    hp.position_sum(p.full, p.n // 2, deadline=d)


def _hub_split(p, d):
    c = _hub_split.counter = Counter(p, native=False)
    hub_split(c, p.full, deadline=d)


def _hub_count(p, d):
    c = _hub_count.counter = Counter(p, native=False)
    h = a_hub(p)
    hub_count(c, p.full, h, [], deadline=d)     # the coupling ignored: only the time is checked here


def _tail(p, d):
    c = _tail.counter = Counter(p, native=False)
    h = a_hub(p)
    TailCounter(c, p.below[h], deadline=d).tail(p.full & ~p.above[h] & ~(1 << h))


ENTRY_POINTS = {
    "Counter.count (compiled where it can)": _count(True),
    "Counter.count (pure Python)": _count(False),
    "Counter.position_sums": _position_sums,
    "Counter.expected_positions": _expected_positions,
    "Counter.sample": _sample,
    "count_linear_extensions": lambda p, d: count_linear_extensions(p, deadline=d),
    "HubPath.count": _hub_path,
    "HubPath.position_sum": _hub_position_sum,
    "hub_split": _hub_split,
    "hub_count": _hub_count,
    "hub_candidates": lambda p, d: hub_candidates(p, p.full, deadline=d),
    "TailCounter.tail": _tail,
    "count_downsets_bounded": lambda p, d: count_downsets_bounded(p, p.full, limit=10 ** 9, deadline=d),
    "upset_counts": lambda p, d: upset_counts(p, p.full, deadline=d),
    "count_by_downsets": lambda p, d: count_by_downsets(p, deadline=d),
    "position_sums_by_downsets": lambda p, d: position_sums_by_downsets(p, deadline=d),
    "earliest_by_order": lambda p, d: earliest_by_order(p, p.full, list(range(p.n)), deadline=d),
    "most_options_by_order": lambda p, d: most_options_by_order(p, p.full, list(range(p.n)), deadline=d),
    "Poset.cover_pairs": lambda p, d: p.cover_pairs(deadline=d),
    "Poset.restrict": lambda p, d: p.restrict(p.full ^ 1, deadline=d),
}


def within(fn, poset: Poset, seconds: float) -> tuple[float, bool]:
    """Run ``fn`` with a deadline ``seconds`` from now: (CPU seconds used, whether it stopped)."""
    # A full collection walks every object of the test process (earlier examples, hypothesis):
    # not the entry point's work, so none runs inside the measured call.
    gc.disable()
    start = time.process_time()
    stopped = False
    try:
        fn(poset, Deadline.after(seconds))
    except BudgetExceeded:
        stopped = True
    finally:
        cpu = time.process_time() - start
        gc.enable()
    return cpu, stopped


ORDERS = {"n": st.sampled_from([200, 700, 3000]), "kind": st.sampled_from(["sparse", "layered"]),
          "seconds": st.sampled_from([0.03, 0.06]), "seed": st.integers(0, 2 ** 16)}


@pytest.mark.parametrize("name", list(ENTRY_POINTS))
@settings(max_examples=2, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(**ORDERS)
def test_every_entry_point_stops_by_its_deadline(name, n, kind, seconds, seed):
    poset = random_order(n, kind, seed)
    fn = ENTRY_POINTS[name]
    cpu, _ = within(fn, poset, seconds)
    assert cpu <= seconds + MARGIN, f"{name} on a {kind} order of {n}: {cpu:.3f} s of CPU for a {seconds} s deadline"
    counter = getattr(fn, "counter", None)
    if counter is not None:
        # the memo the stop left behind still gives exact counts, with no deadline
        small = top(poset)
        assert counter.count(small) == brute_count(poset, small)
        assert counter.count(small & ~(1 << (poset.n - TOP))) == brute_count(poset, small & ~(1 << (poset.n - TOP)))
        fn.counter = None


@settings(max_examples=2, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(**ORDERS)
def test_a_hub_path_stopped_by_its_deadline_still_counts_exactly(n, kind, seconds, seed):
    poset = random_order(n, kind, seed)
    hp = HubPath(poset)
    within(lambda p, d: hp.count(p.full, deadline=d, discover=True), poset, seconds)
    small = top(poset)
    assert hp.count(small) == brute_count(poset, small)
    assert hp.position_sum(small, poset.n - 1) == Counter(poset, native=False).position_sums(small)[poset.n - 1]


@pytest.mark.skipif(not native.available(), reason="the compiled core is not built")
@settings(max_examples=3, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(n=st.sampled_from([100, 250, 600, 1024]), kind=st.sampled_from(["sparse", "layered"]),
       seconds=st.sampled_from([0.02, 0.1]), seed=st.integers(0, 2 ** 16))
def test_the_compiled_core_stops_by_its_deadline_and_keeps_its_memo(n, kind, seconds, seed):
    poset = random_order(n, kind, seed)
    core = native.NativeCounter(poset)
    start = time.process_time()
    status, value, _ = core.count(poset.full, 0, -1, Deadline.after(seconds))
    cpu = time.process_time() - start
    work = core.work()
    assert cpu <= seconds + MARGIN
    assert status in (0, 2)
    assert (status == 0) == (value is not None)
    # what it stored is exact: small sets of the top, counted again from the same memo
    for k in (TOP - 1, TOP):
        small = top(poset, k)
        status, value, _ = core.count(small, 0, -1, -1.0)
        assert status == 0 and value == brute_count(poset, small)
    # the clock is read by work done (counted in word operations): the stopped count did some
    assert work > 0


@pytest.mark.skipif(not native.available(), reason="the compiled core is not built")
def test_a_counter_on_the_compiled_core_gives_the_pure_python_count_after_stops():
    """Stops at many points of one count leave the same exact answer, and short calls in a row
    finish it: a table or arena growth cut by a deadline resumes where it stopped, so no call has
    to grow the whole table within its own budget (which a short budget never allows)."""
    poset = random_order(60, "sparse", 7)
    exact = Counter(poset, native=False).count()
    c = Counter(poset)
    assert c.compiled
    for calls in range(1, 5001):
        try:
            value = c.count(deadline=Deadline.after(0.002))
            break
        except BudgetExceeded:
            pass
    else:
        raise AssertionError("5,000 calls of 2 ms did not finish a count of 20 ms")
    assert value == exact
    # it did stop, and across table growths (the table starts at 1,024 slots and doubles at three
    # quarters full: past 2,048 entries it grew twice; split sets are stored only as a count's root)
    assert calls > 1 and c.memo_size > 2048


def test_the_sooner_deadline_wins_and_legacy_floats_still_work():
    poset = random_order(1000, "sparse", 3)
    c = Counter(poset, native=False)
    c.time_limit = 60.0
    cpu, stopped = within(lambda p, d: c.count(deadline=d), poset, 0.05)
    assert stopped and cpu <= 0.05 + MARGIN
    # a perf_counter moment (the older form) is a deadline too
    start = time.process_time()
    with pytest.raises(BudgetExceeded):
        c.count(deadline=time.perf_counter() + 0.05)
    assert time.process_time() - start <= 0.05 + MARGIN
    # and a passed deadline stops at once; the attribute deadline still works
    c.deadline = time.perf_counter() - 1
    with pytest.raises(BudgetExceeded):
        c.count()


def test_a_feedback_arc_search_stops_by_the_callers_deadline():
    r = random.Random(5)
    nodes = list(range(60))
    arcs = {(r.randrange(60), r.randrange(60)): 1 + r.random() for _ in range(400)}
    start = time.process_time()
    try:
        min_feedback_arc_set(nodes, {a: w for a, w in arcs.items() if a[0] != a[1]}, time_limit=60.0,
                             method="bb", deadline=Deadline.after(0.05))
    except RelaxTimeout as exc:
        assert exc.arcs       # the best set found so far comes with the stop
    except RelaxRefused:      # refused as too large is an answer in time too
        pass
    assert time.process_time() - start <= 0.05 + MARGIN


def test_position_sums_of_wide_orders_match_the_down_set_method():
    """The faster vector fills (no products, no shifts per element) give the same exact sums."""
    for seed in range(6):
        poset = random_order(14, "sparse", seed)
        assert Counter(poset, native=False).position_sums() == position_sums_by_downsets(poset)
    free = Poset.antichain(9)
    sums = Counter(free, native=False).position_sums()
    assert sums == {i: 5 * 362880 for i in range(9)}


@pytest.mark.skipif(not native.available(), reason="the compiled core is not built")
@settings(max_examples=2, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(n=st.sampled_from([100, 120, 250]), kind=st.sampled_from(["sparse", "layered"]),
       seconds=st.sampled_from([0.02, 0.05]), seed=st.integers(0, 2 ** 16))
def test_compiled_tails_and_hub_paths_stop_by_their_deadline(n, kind, seconds, seed):
    """The tail distributions and hub paths of orders small enough for the compiled core run there."""
    poset = random_order(n, kind, seed)
    c = Counter(poset)
    h = a_hub(poset)
    tails = TailCounter(c, poset.below[h])
    cpu, _ = within(lambda p, d: tails.tail(p.full & ~p.above[h] & ~(1 << h), deadline=d), poset, seconds)
    assert cpu <= seconds + MARGIN
    small = top(poset)
    assert c.count(small) == brute_count(poset, small)
    hp = HubPath(poset)          # 2n elements: compiled up to n = 128
    cpu, _ = within(lambda p, d: hp.count(p.full, deadline=d, discover=True), poset, seconds)
    assert cpu <= seconds + MARGIN
    assert hp.count(small) == brute_count(poset, small)
