"""`opportune count --time-limit T` keeps its limit plus COUNT_MARGIN, and a longer limit never makes an exact
count slower.

The orders: sub-DAGs of 128 and 100 nodes of the `pigs` Bayesian network (bnlearn repository, as shipped with
linext's instances), in SALBP .IN2 form in tests/data.

Time is asserted as CPU time (of the command's process, or of this thread), never wall time.
"""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import CpuTime
from opportune.engine import OrderEngine, Schedule
from opportune.engine.schedule import COUNT_MARGIN
from opportune.formats.loader import read_plan

DATA = Path(__file__).parent / "data"
N128 = DATA / "bn_pigs_n128.IN2"      # no count finishes in seconds: every phase runs to its end
N100 = DATA / "bn_pigs_n100.IN2"      # exact through its hub in a tenth of a second


def command(*args: str, prelude: str = "") -> tuple[subprocess.CompletedProcess, float]:
    """``opportune ARGS`` in a fresh process, as the console script runs it, and the CPU seconds it used."""
    code = (prelude + "import sys\nsys.argv = ['opportune', *sys.argv[1:]]\n"
            "from opportune.launch import main\nmain()\n")
    before = os.times()
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120,
                         check=False)
    after = os.times()
    return out, (after.children_user - before.children_user) + (after.children_system - before.children_system)


@pytest.mark.parametrize("path, limit", [(N128, 1.0), (N128, 2.0), (N100, 0.5)])
def test_count_keeps_its_limit_plus_the_margin(path, limit):
    """One thread (so CPU time is at most wall time): the command's CPU time, Python's start-up and the
    imports before the command's clock starts included (measured on a plan that counts at once), is within
    the limit plus COUNT_MARGIN; on the 128-node order every phase runs to its end (relaxation Monte Carlo,
    the hub, the estimate)."""
    start, start_cpu = command("count", "example:gearbox", "--threads", "1")
    assert start.returncode == 0, start.stderr
    out, cpu = command("count", str(path), "--time-limit", str(limit), "--threads", "1")
    assert out.returncode == 0, out.stderr
    assert "admissible sequences" in out.stdout
    assert cpu <= start_cpu + limit + COUNT_MARGIN, (cpu, start_cpu, out.stdout)


def test_the_answer_is_out_before_the_memos_would_be_freed():
    """The command writes its answer and ends without freeing the engine's memos (freeing a hub's tail
    memos took 0.8 s past --time-limit 10 on the 128-node order, and came before the answer); a count
    run in-process (a library, a test runner) still frees them, after the answer."""
    spy = ("import opportune.engine.schedule as s\n"
           "s.OrderEngine.__del__ = lambda self: print('freed', flush=True)\n")
    out, _ = command("count", str(N128), "--time-limit", "0.3", "--threads", "1", prelude=spy)
    assert out.returncode == 0, out.stderr
    assert "admissible sequences" in out.stdout and "freed" not in out.stdout, out.stdout
    out, _ = command("count", str(N128), "--time-limit", "0.3", "--threads", "1", "--json", prelude=spy)
    assert out.returncode == 0 and out.stdout.lstrip().startswith("{") and "freed" not in out.stdout, out.stdout
    from opportune import cli_count

    lines: list[str] = []
    engine = cli_count.run("example:gearbox", None, False, 1.0, 0, 1, load=lambda p: read_plan(p).plan,
                           fail=None, write=lines.append)
    assert engine is None and lines and cli_count.held is None      # nothing kept past the call


def test_a_longer_limit_never_makes_the_exact_count_slower():
    """The 100-node order is exact through its hub within a tenth of a second of CPU time: with a limit of
    10 s and of 60 s alike (the plain count used to get a tenth of the limit first: exact in 1.5 s with 10 s,
    6.6 s with 60 s)."""
    plan = read_plan(str(N100)).plan
    used = {}
    for limit in (10.0, 60.0):
        engine = OrderEngine(plan, max_memo=0, time_limit=limit / 10)     # as `opportune count` makes it
        with CpuTime(thread=True) as cpu:
            result = Schedule(engine).count_result(time_limit=limit * 9 / 10, threads=1)
        assert result.exact, (limit, result)
        used[limit] = cpu.seconds
    assert used[60.0] <= used[10.0] + 0.1, used
    assert used[10.0] <= 1.0, used


def test_a_timed_count_runs_no_collection_of_the_callers_heap(monkeypatch):
    """A cycle collection walks every object of the process (0.3 s for three million), a cost no deadline
    check can bound: none starts inside count_result's work, even with collection thresholds that make one
    start at nearly every allocation; collection is on again afterwards."""
    plan = read_plan(str(N128)).plan
    sched = Schedule(OrderEngine(plan, max_memo=0, time_limit=0.02))
    inside = [False]
    started = []
    real = Schedule._count_timed

    def timed(self, *args):
        inside[0] = True
        try:
            return real(self, *args)
        finally:
            inside[0] = False

    def record(phase, info):
        if phase == "start":
            started.append((inside[0], info["generation"]))

    monkeypatch.setattr(Schedule, "_count_timed", timed)
    thresholds = gc.get_threshold()
    gc.set_threshold(1, 1, 1)
    gc.callbacks.append(record)
    try:
        result = sched.count_result(time_limit=0.2, threads=1)
        [object() for _ in range(10)], [[] for _ in range(10)]     # allocations after it: collections again
    finally:
        gc.callbacks.remove(record)
        gc.set_threshold(*thresholds)
    assert not any(during for during, _ in started) and started, started
    assert gc.isenabled()
    assert not result.exact and result.interval_log10 is not None


def test_collection_is_back_on_once_the_last_of_overlapping_timed_blocks_ends():
    """Counts in several threads (a service): the first block to end must not switch collection back on
    while another still runs, and the last one must."""
    import threading

    from opportune.engine.deadline import no_collection

    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def first():
        with no_collection():
            first_in.set()
            second_in.wait(10)
        first_out.set()

    def second():
        first_in.wait(10)
        with no_collection():
            second_in.set()
            first_out.wait(10)
            seen["after the first ended"] = gc.isenabled()

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen == {"after the first ended": False}
    assert gc.isenabled()
