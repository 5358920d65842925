"""The code's shape where a budget change goes: one module holds the tuning constants, one frozen value
holds a decision's budget.

The engine's and the policies' modules are read with :mod:`ast`: a module-level name in upper case
bound to a number (an int or float literal, an arithmetic of them, or a tuple of them) is a tuning
constant unless it is in ``engine/tuning.py``.  At most :data:`MOST_OUTSIDE` may stay outside (true
unit or format constants, such as a 64-bit mask), so that "make the exact counts run longer" or "give
the probe more of the budget" is one edit in one file.
"""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune.engine import tuning
from opportune.policies.budget import Budget

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "opportune"
ROOMS = ("engine", "policies")
TUNING = PACKAGE / "engine" / "tuning.py"
MOST_OUTSIDE = 5
UPPER = re.compile(r"_?[A-Z][A-Z0-9_]*")


def numeric(node: ast.AST) -> bool:
    """Whether an expression is a number written in the code: a literal, or arithmetic or a tuple of them."""
    if isinstance(node, ast.Constant):
        return type(node.value) in (int, float)
    if isinstance(node, ast.UnaryOp):
        return numeric(node.operand)
    if isinstance(node, ast.BinOp):
        return numeric(node.left) and numeric(node.right)
    if isinstance(node, ast.Tuple):
        return bool(node.elts) and all(numeric(e) for e in node.elts)
    return False


def numeric_constants(path: Path) -> list[tuple[int, str]]:
    """(line, name) of each module-level upper-case name bound to a number in the module at ``path``."""
    found = []
    for statement in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(statement, ast.Assign):
            targets, value = statement.targets, statement.value
        elif isinstance(statement, ast.AnnAssign) and statement.value is not None:
            targets, value = [statement.target], statement.value
        else:
            continue
        if not numeric(value):
            continue
        for target in targets:
            names = target.elts if isinstance(target, ast.Tuple) else [target]
            found += [(statement.lineno, n.id) for n in names if isinstance(n, ast.Name) and UPPER.fullmatch(n.id)]
    return found


def outside_tuning() -> list[str]:
    return [f"{path.relative_to(PACKAGE)}:{line} {name}"
            for room in ROOMS for path in sorted((PACKAGE / room).rglob("*.py")) if path != TUNING
            for line, name in numeric_constants(path)]


def test_the_walk_finds_what_it_counts():
    """The walk is not blind: it finds the tuning module's own constants, tuples and arithmetic included."""
    names = {name for _, name in numeric_constants(TUNING)}
    assert {"COUNT_MARGIN", "EXACT_SHARE", "NATIVE_MAX_BYTES", "RELAX_K_START", "RELAX_K_MAX", "WINDOW_PARTS"} <= names
    assert len(names) > 60


def test_tuning_constants_live_in_one_module():
    outside = outside_tuning()
    assert len(outside) <= MOST_OUTSIDE, "tuning constants outside engine/tuning.py:\n" + "\n".join(outside)


def test_no_class_holds_a_tuning_constant_of_its_own():
    """A class's upper-case attributes (``Lookahead.COMPILED_STATES``, ``Rollout.EXACT_UNITS``) name a line
    of the tuning module, never a number of their own (a test may still patch them on the class)."""
    own = [f"{path.relative_to(PACKAGE)}:{statement.lineno} {node.name}.{target.id}"
           for room in ROOMS for path in sorted((PACKAGE / room).rglob("*.py"))
           for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))) if isinstance(node, ast.ClassDef)
           for statement in node.body if isinstance(statement, ast.Assign) and numeric(statement.value)
           for target in statement.targets if isinstance(target, ast.Name) and UPPER.fullmatch(target.id)]
    assert own == [], "tuning constants in classes:\n" + "\n".join(own)


def test_every_tuning_constant_says_why():
    """Each constant of the tuning module has a line saying why: a ``#:`` block above it (one block may
    document a run of constants written together) or a comment on its own line."""
    lines = TUNING.read_text(encoding="utf-8").splitlines()
    silent = []
    for line, name in numeric_constants(TUNING):
        if "#" in lines[line - 1]:
            continue
        above = line - 2
        while above >= 0 and UPPER.match(lines[above]) and "=" in lines[above]:
            above -= 1      # a constant of the same run
        if above < 0 or not lines[above].startswith("#:"):
            silent.append(name)
    assert not silent, f"tuning constants without a line on why: {silent}"


def test_the_budget_is_frozen_and_made_from_the_tuning_module():
    assert dataclasses.is_dataclass(Budget) and Budget.__dataclass_params__.frozen
    budget = Budget.for_rule(0.05, asks_after=True)
    with pytest.raises(dataclasses.FrozenInstanceError):
        budget.seconds = 1.0
    assert budget.rule_seconds == 0.05 * tuning.THEN_SHARES[0]
    assert budget.margin == tuning.DECISION_MARGIN and budget.exact_share == tuning.EXACT_SHARE
    assert budget.with_seconds(0.1) == Budget.for_rule(0.1, asks_after=True)


def test_a_rule_keeps_its_budget_in_one_frozen_value():
    """A count-based rule's seconds are its Budget's: changing them (as the service does for a look)
    makes a new value, with the same split."""
    from opportune.policies.variants import Slack

    policy = Slack(budget=0.05)
    held = policy.limits
    assert isinstance(held, Budget) and policy.total_budget == 0.05 and policy.budget == held.rule_seconds
    policy.total_budget = 0.1
    assert policy.limits is not held and held.seconds == 0.05
    assert policy.limits.rule_share == held.rule_share and policy.budget == pytest.approx(0.06)


def _tree(relative: str) -> ast.Module:
    return ast.parse((PACKAGE / relative).read_text(encoding="utf-8"))


def test_the_answering_layer_chooses_its_kind_of_answers_once():
    """No method of the answering layer asks which kind of answers it gives (no ``mode == "..."``): each
    kind is a class of one interface, chosen when the answers are made."""
    from opportune.policies.answers import MODES, Answers

    def names_mode(node):
        return (isinstance(node, ast.Attribute) and node.attr == "mode") or (isinstance(node, ast.Name)
                                                                             and node.id == "mode")

    def names_kinds(node):     # a kind's name, names, or the table of them
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return any(names_kinds(e) for e in node.elts)
        return (isinstance(node, ast.Constant) and isinstance(node.value, str)) or (isinstance(node, ast.Name)
                                                                                     and node.id == "MODES")

    switches = [node.lineno for node in ast.walk(_tree("policies/answers.py")) if isinstance(node, ast.Compare)
                and any(names_mode(o) for o in (node.left, *node.comparators))
                and any(names_kinds(o) for o in (node.left, *node.comparators))]
    assert switches == [], f"answers.py switches on its mode at lines {switches}"
    assert list(MODES) == ["order", "exact", "estimate", "then"]
    interface = ("options", "positions", "slack", "picked", "how")
    for name, kind in MODES.items():
        assert kind.name == name and all(callable(getattr(kind, m)) for m in interface)
        ask = Answers(None, 0, 1, (), 1.0, (), mode=name)
        assert type(ask.mode) is kind


def test_the_rules_take_the_state_as_one_value():
    """Inside the policies the six (engine, mask, consistent, buffer, free, visible) travel as one
    LookState: only the public ``choose_at`` form (what a simulation calls), the answering layer's public
    constructor and ``choose_exact`` still take them one by one."""
    clump = {"engine", "mask", "consistent", "buffer", "free", "visible"}
    takers = sorted({f"{path.name}:{node.name}" for path in (PACKAGE / "policies").glob("*.py")
                     for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
                     if isinstance(node, ast.FunctionDef)
                     and clump <= {a.arg for a in node.args.args + node.args.kwonlyargs}})
    assert {t.split(":")[1] for t in takers} <= {"choose_at", "__init__", "choose_exact"}, takers
    assert "answers.py:__init__" in takers and "answers.py:choose_at" in takers   # the walk sees them


def test_the_state_value_is_frozen():
    from opportune import make_plan
    from opportune.engine import OrderEngine
    from opportune.policies.look import LookState

    engine = OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))
    look = LookState(engine, 0, 1, ("b",), 1.0, ("a",))
    with pytest.raises(AttributeError):
        look.mask = 1
    assert look.without_buffer().buffer == () and look.buffer == ("b",)     # a new value; this one kept
    assert tuple(look) == (engine, 0, 1, ("b",), 1.0, ("a",))               # choose_at(*look)


@settings(max_examples=200, deadline=None)
@given(st.floats(1e-4, 100.0), st.booleans(), st.floats(0.0, 1e6), st.floats(0.0, 10.0), st.sampled_from([0, 1]))
def test_the_budget_splits_as_the_rule_did_before_it(seconds, asks_after, start, slow, failed):
    """Every moment and average the Budget gives is the float the rule computed from the module constants
    before the Budget held them (the same operations in the same order), so budgeted decisions keep
    their deadlines to the last bit."""
    b = Budget.for_rule(seconds, asks_after=asks_after)
    rule = seconds * tuning.THEN_SHARES[0] if asks_after else seconds     # the old CountBasedRule.budget
    assert b.rule_seconds == rule
    assert b.end(start) == start + rule * (1 - tuning.DECISION_MARGIN)
    assert b.then_end(start) == start + seconds * (1 - tuning.DECISION_MARGIN)
    assert b.then_exact_seconds == seconds * tuning.THEN_SHARES[1]
    assert b.probe_end(start) == start + rule * tuning.PROBE_SHARE
    share = tuning.EXACT_SHARE[failed]
    assert b.exact_end(start, share) == start + rule * share
    assert b.averaged(slow, 2 * rule) == (1 - tuning.SLOW_WEIGHT) * slow + tuning.SLOW_WEIGHT * 2 * rule
    assert b.averaged(slow, b.failed_reading) == (1 - tuning.SLOW_WEIGHT) * slow + tuning.SLOW_WEIGHT * 2 * rule
    failing = slow > tuning.FAILING * rule
    assert b.is_failing(slow) == failing
    for probe_ok in (0.0, 0.5, 1.0):
        assert b.probe_first(slow, probe_ok) == (slow > tuning.EXACT_FIRST * rule and (failing or probe_ok >= 0.5))
    assert b.band("buffer", int(slow * 10)) == ("buffer", int(slow * 10) // tuning.SIZE_BAND)
