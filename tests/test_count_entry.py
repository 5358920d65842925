"""One counting entry: everything above the engine counts through :class:`~opportune.engine.Schedule`.

The engine chooses how a state is counted (the exact methods of the counter, the hub split, the
estimates): :meth:`Schedule.count_result` and its family (``count``, ``options``, ``options_for``,
``position_sums_for``, ``expected_positions``, ``next_probabilities``, ``sample``, ``completions``,
``warm_up``, ``chains``; :meth:`Schedule.at` for a state held as bitmasks).  No caller above the engine
(policies, sequencer, worlds, study, service, command line, client) picks a door itself: two checks.

* Read from the source (:mod:`ast`): no such module imports the counting modules (the counter, the
  hub, the compiled core, the estimates, the chains, the down-set count), nor calls a counting method
  or a private member of an :class:`~opportune.engine.OrderEngine`.
* Watched at run time: with the engine's counting methods wrapped, a sequencer (warm-up, decisions
  exact and within a budget), a policy's tie check and a small study make every engine count from
  inside :mod:`opportune.engine`.

:mod:`opportune.derive.learn` is the one stated exception: it counts the orders it learns while it
builds a plan, so there is no plan, no engine and no schedule yet to count through; it asks a bare
:class:`~opportune.engine.count.Counter` for exact counts of posets it makes itself.
"""

from __future__ import annotations

import ast
import sys

import pytest
from conftest import GEARBOX
from test_layers import PACKAGE, imported, module_name, source_modules

# The modules above the engine (their layers in tests/test_layers.py).
ABOVE = ("opportune.policies", "opportune.sequencer", "opportune.multi", "opportune.worlds", "opportune.study",
         "opportune.derive", "opportune.service", "opportune.cli", "opportune.cli_count", "opportune.client",
         "opportune.launch", "opportune.__main__")

# The doors behind the entry: the modules that count ...
DOOR_MODULES = {"opportune.engine.count", "opportune.engine.hub", "opportune.engine.native",
                "opportune.engine.estimate", "opportune.engine.relaxmc", "opportune.engine.sampling",
                "opportune.engine.downsets", "opportune._native"}
# ... and the engine's counting methods (its state questions that count nothing stay open: installable
# parts, next units, strategies after an install, its deadline, time limit and upkeep)
DOOR_METHODS = {"count", "options", "options_for", "position_sums", "position_sums_for", "expected_positions",
                "warm_up", "counter", "prepare", "installable_units"}
# The one exception (see the module's text).
EXCEPTIONS = {"opportune.derive.learn"}


def above(module: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in ABOVE)


def _engine_like(node: ast.AST, engines: set[str]) -> bool:
    """An expression that holds an OrderEngine: ``engine``, ``x.engine``, or a local name bound to one."""
    if isinstance(node, ast.Attribute):
        return node.attr == "engine"
    return isinstance(node, ast.Name) and (node.id == "engine" or node.id in engines)


def doors_used(source: str) -> list[str]:
    """Counting doors a module's source uses: imports of :data:`DOOR_MODULES` (not those only for type
    checkers), and calls of :data:`DOOR_METHODS` or private members on an engine (``engine``, ``x.engine``,
    names bound to ``OrderEngine(...)`` or to ``x.engine``), with the line of each."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            node.body = []
    engines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            value = node.value
            made = (isinstance(value, ast.Call) and getattr(value.func, "id", "") == "OrderEngine")
            if made or _engine_like(value, set()):
                engines.add(node.targets[0].id)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            targets = {node.module} | {f"{node.module}.{a.name}" for a in node.names}
            found += [f"line {node.lineno}: imports {t}" for t in sorted(targets & DOOR_MODULES)]
        elif isinstance(node, ast.Import):
            found += [f"line {node.lineno}: imports {a.name}" for a in node.names if a.name in DOOR_MODULES]
        elif isinstance(node, ast.Attribute) and _engine_like(node.value, engines):
            if node.attr in DOOR_METHODS or (node.attr.startswith("_") and not node.attr.startswith("__")):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Attribute) and node.attr == "_make" and getattr(node.value, "id", "") == "Schedule":
            found.append(f"line {node.lineno}: Schedule._make")
    return found


def test_nothing_above_the_engine_opens_a_counting_door():
    used = {}
    for name, path in source_modules().items():
        if above(name) and name not in EXCEPTIONS:
            found = doors_used(path.read_text(encoding="utf-8"))
            if found:
                used[name] = found
    assert not used, "count through opportune.engine.Schedule (count_result and its family, Schedule.at):\n" + \
        "\n".join(f"{m}: {', '.join(f)}" for m, f in sorted(used.items()))


def test_the_import_graph_agrees():
    """A second reading, by the layer test's import walk (relative imports, lazy tables, ``import_module``):
    no module outside the engine imports a counting module but the stated exception."""
    modules = source_modules()
    known = set(modules) | {"opportune._native"}
    graph = {name: imported(name, path, known, typing=False) for name, path in modules.items()}
    outside = {m for m, t in graph.items() if t & DOOR_MODULES and not m.startswith("opportune.engine")}
    assert outside == EXCEPTIONS, outside
    assert all(above(m) for m in EXCEPTIONS)


def test_the_reader_finds_each_kind_of_door():
    """Each kind of door the check looks for is found in a snippet (so that a clean package means something)."""
    snippet = "\n".join([
        "from opportune.engine.count import Counter",
        "from opportune.engine import native",
        "import opportune.engine.hub",
        "def f(state, plan):",
        "    state.schedule.engine.options_for(0, 1, ['a'])",
        "    e = OrderEngine(plan)",
        "    e.count(0, 1)",
        "    other = state.engine",
        "    other._terms(1)",
        "    engine.warm_up(1.0)",
        "    Schedule._make(e, (), 0, 1)",
        "    e.installable(0, 1)",          # no count: allowed
        "    e.next_unit(0, 1)",
        "    [1, 2].count(1)",
        "TYPE_CHECKING = False",
        "if TYPE_CHECKING:",
        "    from opportune.engine.sampling import CompletionChains",   # never runs: allowed
    ])
    found = doors_used(snippet)
    assert [f.split(":")[0] for f in found] == [f"line {i}" for i in (1, 2, 3, 5, 7, 9, 10, 11)], found


def test_the_exception_counts_bare_posets_only():
    """derive.learn has no plan to make a schedule of: it opens the bare counter and no other door."""
    path = PACKAGE / "derive" / "learn.py"
    assert module_name(path) in EXCEPTIONS
    found = doors_used(path.read_text(encoding="utf-8"))
    assert found and all(f.endswith("imports opportune.engine.count") for f in found), found


@pytest.fixture
def counts_from(monkeypatch):
    """The modules that call the engine's counting methods directly, while the fixture is active."""
    from opportune.engine.schedule import OrderEngine

    callers: dict[str, int] = {}

    def watch(name):
        method = getattr(OrderEngine, name)

        def watched(self, *args, **kwargs):
            caller = sys._getframe(1).f_globals.get("__name__", "?")
            callers[caller] = callers.get(caller, 0) + 1
            return method(self, *args, **kwargs)

        monkeypatch.setattr(OrderEngine, name, watched)

    for name in DOOR_METHODS:
        watch(name)
    return callers


def test_callers_count_through_the_entry_at_run_time(counts_from):
    from opportune import load_plan
    from opportune.engine import OrderEngine
    from opportune.policies.opportunistic import Opportunistic
    from opportune.sequencer import Sequencer
    from opportune.study.simulate import StudyConfig, run_study

    plan = load_plan(GEARBOX)
    engine = OrderEngine(plan)
    for budget in (None, 1e-4):      # exact; and within a tiny budget (the estimates' chains)
        seq = Sequencer(engine, Opportunistic(budget=budget), warm_up=1.0)
        assert seq.warmed
        for _ in range(3):
            looks = seq.state.schedule.installable()[:2]
            decision = seq.decide(visible=list(looks))
            seq.report("success" if decision.action.kind != "shake" else "failed")
    assert Opportunistic().buffer_ties_at(engine, 0, engine.all_strategies) is not None
    result = run_study(StudyConfig(plan=plan, strategies=("paper",), trials=3, seed=2), workers=1)
    assert result is not None
    assert counts_from, "the run made no count at all: the watch is broken"
    outside = {m: n for m, n in counts_from.items() if not m.startswith("opportune.engine")}
    assert not outside, f"counted past the entry: {outside}"


def test_the_watch_sees_a_direct_call(counts_from):
    """A count made outside the engine is seen (so that the run-time check can fail)."""
    from opportune import make_plan
    from opportune.engine import OrderEngine

    engine = OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))
    assert engine.count(0, engine.all_strategies) == 1
    assert counts_from.get(__name__) == 1
