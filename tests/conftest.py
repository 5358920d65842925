"""Shared test helpers: where the shared data lives, brute-force references, random plans."""

from __future__ import annotations

import itertools
import os
import time
from pathlib import Path

import pytest
from hypothesis import strategies as st


REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
GEARBOX = EXAMPLES / "gearbox.yaml"


BENCHMARKS = REPO / "benchmarks"


def benchmark(module: str):
    """A module of ``benchmarks/`` (the policy lab, the fallback's diagnosis), imported with that folder on
    the path (the scripts import one another by name)."""
    import importlib
    import sys

    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    return importlib.import_module(module)


def lab_plan(name: str, low: int | None = None, high: int | None = None):
    """One of the policy lab's seed-0 plans by name (r2-16x2: of 16 parts, two strategies), drawn as the lab
    draws its group of ``low``-``high`` parts (default: the size in its name; r3-11 is of the 8-12 group)."""
    size = int(name.split("-")[1].split("x")[0])
    plans = benchmark("policy_lab").generate(0, 30, low or size, high or size)
    return {p.name: p for p, _ in plans}[name]


def salbp_dir() -> Path:
    """The SALBP graphs shipped inside the package (opportune/datasets/salbp)."""
    from opportune import datasets

    return datasets.salbp_path("KILBRID").parent


@pytest.fixture(scope="session")
def salbp() -> Path:
    return salbp_dir()


@pytest.fixture(scope="session")
def postgres():
    """A throwaway PostgreSQL server for the session (`make test` installs the server programs)."""
    from opportune.service.testing import PostgresServer

    with PostgresServer() as pg:
        yield pg


def salbp_poset(name: str):
    """A shared SALBP graph (by file stem) as an engine Poset, read with the package's own .IN2 reader."""
    from opportune.engine.poset import Poset
    from opportune.formats.salbp import read_in2

    graph = read_in2(salbp_dir() / f"{name}.IN2")
    return Poset.from_pairs(graph.n, [(a - 1, b - 1) for a, b in graph.pairs])


SALBP_FILES = ["MERTENS", "BOWMAN8", "JAESCHKE", "JACKSON", "MANSOOR", "MITCHELL", "HESKIA", "KILBRID", "TONGE70", "ARC111"]


# ---------------------------------------------------------------- time bounds that hold under load
#
# No test asserts a wall-clock bound: on a busy machine (other jobs on every core) a correct program
# takes as long as the scheduler lets it.  Where a bound is the point, it is asserted on the CPU time
# the process under test spent (what the program itself did), on an injected clock, or on counted
# work.  Waits that only stop a hung test (a server that never comes up) may use the wall clock.


class CpuTime:
    """CPU seconds (user + system, every thread) this process spends inside a ``with`` block.

    ``seconds`` reads the time so far inside the block and the total after it.  The service's test
    servers run in threads of the test process, so their work is counted too.  ``thread=True``
    counts the calling thread only: for work done in it (the engine's), so that a background thread
    an earlier test left in this worker process (a warm-up winding down) is not counted.

    >>> with CpuTime() as cpu:
    ...     _ = sum(range(10))
    >>> 0 <= cpu.seconds < 1
    True
    """

    def __init__(self, thread: bool = False):
        self.start = self.end = None
        self.clock = time.thread_time if thread else time.process_time

    @classmethod
    def begin(cls) -> CpuTime:
        """A timer already running (for a span that is not one block)."""
        return cls().__enter__()

    def __enter__(self) -> CpuTime:
        self.start = self.clock()
        return self

    def __exit__(self, *exc) -> None:
        self.end = self.clock()

    @property
    def seconds(self) -> float:
        return (self.end if self.end is not None else self.clock()) - self.start


@pytest.fixture
def cpu_time():
    """A fresh :class:`CpuTime` factory: ``with cpu_time() as cpu: ...; assert cpu.seconds < 1``."""
    return CpuTime


def process_cpu_seconds(pid: int) -> float:
    """CPU seconds (user + system, all its threads) another live process has used so far, from
    ``/proc/PID/stat`` (for a server in a child process; no psutil)."""
    with open(f"/proc/{pid}/stat") as f:
        # the command name (field 2) may hold spaces and parentheses: split after its last ')'
        fields = f.read().rsplit(")", 1)[1].split()
    # fields[0] is field 3 (state): utime and stime are fields 14 and 15
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# ---------------------------------------------------------------- brute force


def multiset_permutations(items):
    """Distinct orderings of a multiset (as tuples), in lexicographic order: each from the one before by the
    classic next-permutation step (Narayana Pandita), so none is made twice and none is filtered out.

    n!/(m1!...mk!) orderings of O(n) each; distinct items go through itertools (C), in the same order.

    >>> list(multiset_permutations("aba"))
    [('a', 'a', 'b'), ('a', 'b', 'a'), ('b', 'a', 'a')]
    """
    a = sorted(items)
    if len(set(a)) == len(a):
        yield from itertools.permutations(a)
        return
    n = len(a)
    while True:
        yield tuple(a)
        i = n - 2                      # the last ascent: a[i] < a[i + 1]
        while i >= 0 and a[i] >= a[i + 1]:
            i -= 1
        if i < 0:
            return                     # descending: the last ordering
        j = n - 1                      # the last item larger than a[i] goes there, the tail reversed
        while a[j] <= a[i]:
            j -= 1
        a[i], a[j] = a[j], a[i]
        a[i + 1:] = a[:i:-1]


def spans(seq) -> tuple[dict, dict]:
    """``(first, last)``: each part's first and last position in ``seq``."""
    first, last = {}, {}
    for i, p in enumerate(seq):
        first.setdefault(p, i)
        last[p] = i
    return first, last


def respects(seq, strategy) -> bool:
    """Every unit of each part comes after every unit of the parts it requires."""
    first, last = spans(seq)
    return all(last[b] < first[a] for a, bs in strategy.requires.items() for b in bs)


def brute_sequences(plan, prefix=()):
    """All admissible complete sequences of part ids starting with ``prefix`` (brute force: every ordering of
    the remaining units, kept if it respects some strategy, as :func:`respects` checks)."""
    units = [p.id for p in plan.parts for _ in range(p.quantity)]
    remaining = list(units)
    for p in prefix:
        remaining.remove(p)
    prefix = tuple(prefix)
    # each strategy's constraints as (before, after) pairs, listed once rather than for every ordering
    orders = [[(b, a) for a, bs in s.requires.items() for b in bs] for s in plan.strategies]
    out = []
    for rest in multiset_permutations(remaining):
        first, last = spans(prefix + rest)
        if any(all(last[b] < first[a] for b, a in pairs) for pairs in orders):
            out.append(rest)
    return out


# ---------------------------------------------------------------- random plans


@st.composite
def random_plans(draw, max_parts=6, max_units=8, max_strategies=3, quantities=True):
    n = draw(st.integers(1, max_parts))
    ids = [f"p{i}" for i in range(n)]
    qty = [1] * n
    if quantities:
        for i in range(n):
            if sum(qty) < max_units:
                qty[i] = draw(st.integers(1, min(3, max_units - sum(qty) + 1)))
    k = draw(st.integers(1, max_strategies))
    strategies = {}
    for s in range(k):
        order = draw(st.permutations(range(n)))
        req: dict[str, list[str]] = {}
        for j in range(n):
            for i in range(j):
                if draw(st.booleans()) and draw(st.booleans()):
                    req.setdefault(ids[order[j]], []).append(ids[order[i]])
        strategies[f"s{s}"] = req
    parts = [{"id": ids[i], "quantity": qty[i]} if qty[i] > 1 else ids[i] for i in range(n)]
    from opportune.formats import plan_from_dict

    doc = {"name": "random", "parts": parts,
           "strategies": [{"name": name, "requires": req} for name, req in strategies.items()]}
    # Identical strategies are an error in a plan file; keep the first of each.
    from opportune.formats.loader import Document
    from opportune.formats.validate import check_document

    result = check_document(Document(doc))
    if not result.ok:
        seen, unique = [], []
        for s in doc["strategies"]:
            key = {a: sorted(b) for a, b in s["requires"].items()}
            if key not in seen:
                seen.append(key)
                unique.append(s)
        doc["strategies"] = unique
        result = check_document(Document(doc))
        if not result.ok:  # same order declared differently (e.g. redundant arcs): keep one strategy
            doc["strategies"] = unique[:1]
    return plan_from_dict(doc)



def policy_run(policy, engine, visible: int, capacity: int, rng, steps: int) -> list:
    """A policy's actions (``choose_at``) along a run whose looks are drawn from the bin by ``rng``: at most
    ``steps`` decisions, each action carried out on the state (a buffered part leaves the buffer once)."""
    plan, mask, cons, buffer, out = engine.plan, 0, engine.all_strategies, (), []
    for _ in range(steps):
        if mask == engine.full:
            break
        in_bin = [p for i, p in enumerate(plan.part_ids) if engine.next_unit(mask, i) is not None and p not in buffer]
        action = policy.choose_at(engine, mask, cons, buffer, capacity - len(buffer),
                                  tuple(rng.sample(in_bin, min(visible, len(in_bin)))))
        out.append(action)
        if action.kind == "buffer":
            buffer += (action.part,)
        elif action.kind == "install":
            unit = engine.next_unit(mask, plan.index(action.part))
            mask, cons = mask | 1 << unit, engine.consistent_after(mask, cons, unit)
            if action.source == "buffer":
                buffer = tuple(sorted(buffer, key=lambda p: p != action.part))[1:]
    return out


def run_cli(*args):
    """Run ``opportune ARGS`` in process (typer's runner) and return the result, after checking what every
    command line test needs: no traceback, and no exception other than the exit."""
    from typer.testing import CliRunner

    from opportune.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result


# ---------------------------------------------------------------- order: the longest tests first
#
# `make test` runs on two workers (pytest-xdist): a long test that starts last keeps one worker busy
# while the other idles.  These (tens of seconds each, measured with --durations) and tests marked
# `slow` start first; everything else keeps its order.  Run serially, the order changes nothing else.
LONGEST_FIRST = (
    "tests/test_openapi.py::test_schemathesis_follows_the_links",
    "tests/test_reproducible.py::test_two_runs_of_the_demo_write_the_same_files",
    "tests/test_readme.py::test_every_readme_command_runs_from_an_empty_directory[simulate",
    "tests/test_engine_hub.py::test_arc111_exact_through_its_hub",
    "tests/test_service_scaleout.py::test_two_processes_kill_9_under_load",
    "tests/test_service_plan_memory.py::test_the_servers_resident_memory_is_kept_under_its_cap",
    "tests/test_service_browser.py::test_dashboard_frontier_on_large_plans",
    "tests/test_service_browser.py::test_arc111_is_legible_at_1280x800_and_its_progress_shows",
    "tests/test_pile_bin.py::test_lookahead_on_the_piles_own_programme",
    "tests/test_service_scaleout.py::test_serve_workers_2_replaces_a_killed_worker",
    "tests/test_memory_limit.py::test_a_long_run_stays_near_its_engines_limit",
    "tests/test_docs.py::test_the_site_builds_offline",
    "tests/test_docs.py::test_the_examples_of_a_page_run",
    "tests/test_memory_limit.py::test_an_engine_keeps_its_memos_within_its_limit",
    "tests/test_engine_native.py::test_compiled_equals_pure_python_on_random_orders",
    "tests/test_engine_count_scans.py::test_narrow_and_wide_scans_agree",
    "tests/test_reproducible.py::test_a_recorded_study_runs_again",
    "tests/test_openapi.py::test_schemathesis_finds_answers_as_documented",
    "tests/test_openapi.py::test_schemathesis_with_an_operator_token_finds_answers_as_documented",
    "tests/test_engine_count.py::test_salbp_decomposition_agrees_with_downsets",
    "tests/test_service_restart.py::test_kill_9_under_load",
    "tests/test_opcua.py::test_kill_9_under_a_driving_opcua_client",
    "tests/test_opcua.py::test_table_1_over_opcua",
    "tests/test_physics_bin.py::test_every_policy_completes_on_the_physical_bin",
    "tests/test_plain_yaml.py::test_mutated_documents_are_read_as_pyyaml_reads_them_or_declined",
)


def _first_rank(item) -> int:
    if item.get_closest_marker("slow"):
        return 0
    for rank, prefix in enumerate(LONGEST_FIRST, start=1):
        if item.nodeid.startswith(prefix):
            return rank
    return len(LONGEST_FIRST) + 1


def pytest_collection_modifyitems(config, items):
    items.sort(key=_first_rank)      # stable: tests of equal rank keep their collected order
