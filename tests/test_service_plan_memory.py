"""Per-plan work in the service: built once per plan and shared by its runs, accounted in bytes, kept under a cap.

No wall-clock bounds: work is counted (engines built, warm-up slices, evictions) or measured in CPU time.
"""

from __future__ import annotations

import random
import sys
import time

import pytest

from conftest import GEARBOX, CpuTime
from opportune import load_plan, make_plan

pytest.importorskip("fastapi")
pytest.importorskip("sqlalchemy")

from fastapi.testclient import TestClient

from opportune.service.app import create_app
from opportune.service.auth import create_token
from opportune.service.config import Settings
from opportune.service.plans import min_working_set
from opportune.service.storage import Store


class Cell:
    """A cell's client of an in-process service (a fresh Idempotency-Key on every POST)."""

    def __init__(self, tmp_path, **settings):
        url = f"sqlite:///{tmp_path / 'mem.db'}"
        self.store = Store(url)
        self.headers = {"Authorization": f"Bearer {create_token(self.store, cell='c1')[1]}"}
        self.op = {"Authorization": f"Bearer {create_token(self.store, operator='op')[1]}"}
        self.app = create_app(Settings(db_url=url, max_body=1 << 22, **settings), self.store)
        self.book = self.app.state.manager.book
        self.keys = 0

    def __enter__(self):
        self.client = TestClient(self.app).__enter__()
        return self

    def __exit__(self, *exc):
        self.client.__exit__(*exc)
        self.store.dispose()

    def post(self, path, body, expect=200):
        self.keys += 1
        r = self.client.post(path, json=body, headers={**self.headers, "Idempotency-Key": f"k{self.keys}"})
        assert r.status_code == expect, r.text
        return r.json()

    def upload(self, plan) -> str:
        return self.post("/plans", plan.to_dict(), expect=201)["id"]

    def drive(self, run_id: int, looks) -> list[dict]:
        """Send each look and report success; the actions decided."""
        actions = []
        for look in looks:
            answer = self.post(f"/runs/{run_id}/looks", {"visible": look})
            actions.append(answer["action"])
            if self.post(f"/runs/{run_id}/outcomes", {"outcome": "success"})["run"]["status"] == "complete":
                break           # the last part is in: the run takes no more looks
        return actions


def library_run(plan, seed: int, n: int, *, budget=None) -> tuple[list[list[str]], list[dict]]:
    """Looks of a uniform bin (two parts from those left in it) through a fresh library sequencer on a
    fresh engine, with the service's default policy, every action succeeding: ``(looks, actions)``.
    The same looks sent to a run that decides alike keep fitting its state."""
    from opportune.engine import OrderEngine
    from opportune.policies.named import DEFAULT_POLICY, make_policy
    from opportune.sequencer import Sequencer

    rng = random.Random(seed)
    sim = plan.simulation
    seq = Sequencer(OrderEngine(plan), make_policy(DEFAULT_POLICY, budget=budget, visible=sim.get("visible", 2)),
                    budget=budget, warm_up=0)
    looks, actions = [], []
    for _ in range(n):
        in_bin = [p for p, k in sorted(seq.state.in_bin.items()) for _ in range(k)]
        look = rng.sample(in_bin, min(2, len(in_bin)))
        d = seq.decide(look)
        looks.append(look)
        actions.append(d.action.to_dict())
        if d.action.kind == "done":
            break
        seq.report("success")
    return looks, actions


def layered(n: int, seed: int):
    """A plan of ``n`` parts in layers of five, each part needing one or two of the layer below."""
    rng = random.Random(seed)
    ids = [f"s{seed}p{i}" for i in range(n)]
    requires = {ids[i]: rng.sample(ids[max(0, i - i % 5 - 5): i - i % 5], min(2, i - i % 5)) for i in range(5, n)}
    return make_plan(ids, requires, name=f"layered-{seed}")


def test_runs_of_one_plan_share_its_engine_and_its_warm_up(tmp_path):
    """Two runs of a plan: one engine (identity), one warm-up (its slices are not repeated by the second
    run), and the decisions of a fresh library sequencer on a fresh engine."""
    plan = load_plan(GEARBOX)
    with Cell(tmp_path) as cell:
        pid = cell.upload(plan)
        first = cell.post("/runs", {"plan": pid, "policy": "paper"}, expect=201)
        (loaded,) = cell.book.loaded()
        assert loaded.warm == "done" and loaded.warm_slices == 1     # the gearbox counts within the first slice
        assert first["count"]["value"] == "336"
        second = cell.post("/runs", {"plan": pid, "policy": "paper"}, expect=201)
        assert loaded.warm_slices == 1 and cell.book.loads == 1        # nothing of the plan was redone
        live = cell.app.state.manager._live
        assert live[first["id"]].sequencer.engine is live[second["id"]].sequencer.engine is loaded.engine
        looks = [["rl", "ra"], ["ca", "ba"], ["ba", "sm"], ["sm", "st"], ["dr", "ml"], ["ml", "cl"], ["co", "ra"]]
        a = cell.drive(first["id"], looks)
        b = cell.drive(second["id"], looks)
    assert a == b
    from opportune.engine import OrderEngine
    from opportune.policies.opportunistic import Opportunistic
    from opportune.sequencer import Sequencer

    # the paper's rule: on the gearbox every decision is exact within the budget, so alike in any process
    fresh = Sequencer(OrderEngine(plan), Opportunistic(budget=0.05), warm_up=0)
    assert a == [fresh.step(look).action.to_dict() for look in looks]


def test_a_plan_over_its_memory_share_is_refused_at_upload_and_not_stored(tmp_path):
    big = make_plan([f"p{i}" for i in range(3000)], {}, name="free-3000")
    cap = 16 << 20
    assert min_working_set(big) > cap // 2         # its share: half the cap
    with Cell(tmp_path, memory_cap=cap, plan_share=0.5) as cell:
        r = cell.client.post("/plans", json=big.to_dict(), headers={**cell.headers, "Idempotency-Key": "x"})
        assert r.status_code == 413, r.text
        err = r.json()["error"]
        assert err["code"] == "plan_too_large_for_memory"
        assert "3,000 units" in err["message"] and "MB" in err["message"] and "memory cap" in err["hint"]
        assert cell.client.get("/plans", headers=cell.op).json()["plans"] == []    # nothing stored
        assert cell.book.loaded() == []                                             # nothing built
        small = cell.upload(load_plan(GEARBOX))                                     # a plan within its share
        cell.post("/runs", {"plan": small}, expect=201)


def test_a_memory_cap_evicts_whole_plans_and_an_evicted_plan_decides_as_before(tmp_path):
    """Plans uploaded and run in a loop under a cap of about one of them: the accounted bytes
    stay under the cap after every request, least recently used plans are evicted, and a run of an
    evicted plan goes on (rebuilt from its log on a new engine) with the decisions of a fresh engine."""
    plans = [layered(30, seed) for seed in range(4)]
    expected = {p.name: library_run(p, 7, 6) for p in plans}
    looks = {name: lk for name, (lk, _) in expected.items()}
    with Cell(tmp_path, decision_budget=None, plan_share=1.0) as cell:
        pids = [cell.upload(p) for p in plans]
        run0 = cell.post("/runs", {"plan": pids[0]}, expect=201)["id"]
        cell.drive(run0, looks[plans[0].name][:2])
        one = cell.book.loaded()[0].measure()
        cell.book.memory_cap = int(1.2 * one)     # about one plan's worth: the plans take turns
        runs = {pids[0]: run0}
        decided = {pids[0]: cell.drive(run0, [])}
        for rnd in range(2):
            for pid, plan in zip(pids, plans):
                if pid not in runs:
                    runs[pid] = cell.post("/runs", {"plan": pid}, expect=201)["id"]
                    decided[pid] = []
                start = 2 * rnd if pid != pids[0] else 2 + 2 * rnd
                decided[pid] += cell.drive(runs[pid], looks[plan.name][start:start + 2])
                assert cell.book.nbytes() <= cell.book.memory_cap
        assert cell.book.evictions >= 2 and cell.book.loads > len(plans)
        # run 0's plan was evicted and loaded again: its first two looks came before, on the first engine
        for pid, plan in zip(pids, plans):
            n = 6 if pid == pids[0] else 4
            done = cell.client.get(f"/runs/{runs[pid]}/trace", headers=cell.headers).json()["rows"]
            assert [row["action"] for row in done][:n] == expected[plan.name][1][:n]


def test_run_start_does_bounded_work_on_a_plan_it_cannot_count_at_once(tmp_path):
    """A plan whose first state is not counted within the start's warm-up: the first run starts after one
    bounded foreground slice (its count null), the warm-up goes on in the background and stops within its
    time; the second run's start repeats none of it.  CPU time only."""
    rng = random.Random(1)
    bottom, top = [f"b{i}" for i in range(30)], [f"t{i}" for i in range(30)]
    wide = make_plan(bottom + top, {t: rng.sample(bottom, 3) for t in top}, name="wide")
    with Cell(tmp_path, warm_up_seconds=0.3, count_seconds=0.05) as cell:
        pid = cell.upload(wide)
        with CpuTime() as cpu:
            first = cell.post("/runs", {"plan": pid}, expect=201)
        assert cpu.seconds < 5
        (loaded,) = cell.book.loaded()
        for _ in range(400):                    # the background warm-up ends by its own deadline
            if loaded.warm != "running":
                break
            time.sleep(0.01)
        assert loaded.warm in ("stopped", "done")
        slices = loaded.warm_slices
        with CpuTime() as cpu:
            second = cell.post("/runs", {"plan": pid}, expect=201)
        assert cpu.seconds < 2
        assert loaded.warm_slices == slices and cell.book.loads == 1
        if loaded.warm != "done":
            assert first["count"] is None and second["count"] is None   # not counted: null, not waited for
        answer = cell.post(f"/runs/{second['id']}/looks", {"visible": ["t0", "b3"]})
        assert answer["action"]["kind"] in ("install", "buffer")


def test_an_engines_accounted_bytes_follow_what_it_allocates():
    """The sampled estimate against what tracemalloc sees the counts allocate (pure-Python memos)."""
    import tracemalloc

    from opportune.engine import OrderEngine, Schedule

    plan = layered(40, 3)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        engine = OrderEngine(plan, max_memo=None)
        for c in [engine.counter(1)]:
            c._native = None                 # the compiled memo is outside tracemalloc's view
        s = Schedule(engine)
        for part in plan.part_ids[:10]:
            s.expected_positions()
            s = s.install(part) if s.can_install(part) else s
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    accounted = engine.nbytes()
    assert grown > 100_000, "the counts should allocate memos"
    assert 0.3 * grown < accounted < 3 * grown, (accounted, grown)
    assert sys.getsizeof(engine) < accounted


def test_a_hub_paths_accounted_bytes_grow_with_its_memos():
    from opportune.engine.count import Counter
    from opportune.engine.hub import HubPath
    from opportune.engine.poset import Poset

    p = Poset.from_pairs(6, [(0, 2), (1, 2), (2, 3), (4, 3), (2, 5)])
    hub = HubPath(p)
    empty = hub.nbytes()
    assert hub.count(p.full, discover=True) == Counter(p).count()
    assert hub.nbytes() > empty > 0       # its counter's memo (and tails, where it found a hub)


def test_the_servers_resident_memory_is_kept_under_its_cap_by_shrinking_then_evicting(tmp_path):
    """The process's resident memory read through an injected reading that is twice the engines' live
    bytes (the allocator's slack, fragmentation): past the cap, the plans' memos are shrunk (their runs
    go on, with the decisions of a fresh engine), then plans evicted; after every outcome the reading is
    under the cap again."""
    plans = [layered(40, seed) for seed in range(3)]
    expected = {p.name: library_run(p, 5, 12) for p in plans}
    with Cell(tmp_path, decision_budget=None, plan_share=1.0) as cell:
        book = cell.book

        def reading():
            return book.baseline + 2 * sum(p.engine.nbytes() for p in book.loaded())

        pids = [cell.upload(p) for p in plans]
        runs = {pid: cell.post("/runs", {"plan": pid}, expect=201)["id"] for pid in pids}
        cell.drive(runs[pids[0]], expected[plans[0].name][0][:1])
        book.resident = reading
        book.memory_cap = int(3.0 * book.loaded()[0].engine.nbytes())
        decided = {pid: [] for pid in pids}
        decided[pids[0]].append(expected[plans[0].name][1][0])
        for k in range(12):
            for pid, plan in zip(pids, plans):
                if k == 0 and pid == pids[0]:
                    continue
                decided[pid] += cell.drive(runs[pid], [expected[plan.name][0][k]])
                assert reading() - book.baseline <= book.memory_cap
        assert book.shrinks >= 1
        for pid, plan in zip(pids, plans):
            assert decided[pid] == expected[plan.name][1]


def test_resident_memory_rules_locks_high_water_rearm_and_the_plan_at_work(tmp_path):
    """Plans whose locks are held (inside a decision) are neither shrunk nor evicted, however high the
    reading: the next request between decisions does it.  Past the high water (under the cap) the memos
    are shrunk and nothing is evicted, and nothing is done again until the reading grows; over the cap
    itself, least recently used plans are evicted, never the most recently used one."""
    with Cell(tmp_path, decision_budget=None) as cell:
        book = cell.book
        old = cell.upload(layered(20, 1))
        cell.post("/runs", {"plan": old}, expect=201)
        pid = cell.upload(layered(20, 2))
        cell.post("/runs", {"plan": pid}, expect=201)
        first, last = book.loaded()
        reading = [book.baseline + int(0.9 * book.memory_cap)]     # over the high water, under the cap
        book.resident = lambda: reading[0]
        with first.lock, last.lock:
            book.settle()
        assert book.shrinks == 0 and book.evictions == 0
        book.settle()
        assert book.shrinks == 2 and book.evictions == 0 and book.loaded() == [first, last]
        book.settle()
        assert book.shrinks == 2                # the reading has not grown since: nothing more to do yet
        reading[0] = book.baseline + 10 * book.memory_cap               # over the cap itself
        book.settle()
        assert book.shrinks == 4 and book.evictions == 1 and book.loaded() == [last]   # never the plan at work
