"""GraphML and DOT precedence graphs in and out, NetworkX graphs, and `opportune convert`."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from conftest import GEARBOX, random_plans
from opportune import load_plan, make_plan
from opportune.cli import app
from opportune.engine import OrderEngine
from opportune.engine.poset import Poset
from opportune.formats.graphfiles import check_dot_bytes, check_graphml_bytes, plan_from_networkx, to_dot_precedence, to_graphml
from opportune.planning.plan import PlanError

runner = CliRunner()


def closure(plan, k: int) -> frozenset:
    """A strategy's order as its transitive closure on part ids (what a file must preserve)."""
    ids = plan.part_ids
    pairs = [(ids.index(a), ids.index(b)) for b, before in plan.strategies[k].requires.items() for a in before]
    p = Poset.from_pairs(len(ids), pairs)
    return frozenset((ids[a], ids[b]) for b in range(len(ids)) for a in range(len(ids)) if p.less(a, b))


def same(plan, back) -> None:
    assert back.part_ids == plan.part_ids
    assert [(p.quantity, p.name or p.id) for p in back.parts] == [(p.quantity, p.name or p.id) for p in plan.parts]
    assert len(back.strategies) == len(plan.strategies)
    for k in range(len(plan.strategies)):
        assert closure(back, k) == closure(plan, k)
    assert OrderEngine(back).count(0, OrderEngine(back).all_strategies) == \
        OrderEngine(plan).count(0, OrderEngine(plan).all_strategies)


@settings(max_examples=40, deadline=None)
@given(plan=random_plans(max_parts=7, max_units=9, max_strategies=3))
def test_graphml_round_trip_keeps_every_strategy(plan):
    result = check_graphml_bytes(to_graphml(plan).encode(), file="p.graphml")
    assert result.ok, [str(p) for p in result.problems]
    same(plan, result.plan)
    assert result.plan.name == plan.name


@settings(max_examples=40, deadline=None)
@given(plan=random_plans(max_parts=7, max_units=9, max_strategies=1))
def test_dot_round_trip(plan):
    result = check_dot_bytes(to_dot_precedence(plan).encode(), file="p.dot")
    assert result.ok, [str(p) for p in result.problems]
    same(plan, result.plan)


def test_the_gearbox_through_every_format(tmp_path):
    plan = load_plan(GEARBOX)
    for fmt in ("yaml", "json", "graphml", "dot", "alb"):
        out = tmp_path / f"gearbox.{fmt}"
        r = runner.invoke(app, ["convert", str(GEARBOX), str(out)])
        assert r.exit_code == 0, r.output
        back = load_plan(out)
        assert OrderEngine(back).count(0, 1) == 336
        if fmt != "alb":                 # .alb names tasks 1..n, and says so
            assert back.part_ids == plan.part_ids and back.name == plan.name
        else:
            assert back.part_ids == tuple(str(i) for i in range(1, 11))
            assert "1 = ca" in r.stderr and "not kept" in r.stderr
    # two strategies: GraphML keeps both; DOT and .alb hold one, and say so
    import json

    two = make_plan(["a", "b", "c"], strategies={"x": {"c": ["a"]}, "y": {"c": ["b"]}})
    path = tmp_path / "two.json"
    path.write_text(json.dumps(two.to_dict()))
    r = runner.invoke(app, ["convert", str(path), "-", "--to", "graphml"])
    assert r.exit_code == 0 and r.output.count("<graph ") == 2
    r = runner.invoke(app, ["convert", str(path), str(tmp_path / "two.dot")])
    assert r.exit_code == 2 and "2 strategies" in r.output


@pytest.mark.parametrize("text,line,words", [
    (b"digraph g {\n  a -> b;\n  b -- c;\n}\n", 3, "undirected edge"),
    (b"graph g { a -- b }", 1, "undirected"),
    (b"graph g { a }", 1, "undirected graph"),
    (b"digraph g {\n a -> b\n", 2, "closing"),
    (b"digraph g {\n a -> b;\n b -> c;\n c -> a;\n}", 2, "cycle"),
    (b"digraph g {\n a [quantity=lots];\n}", 2, "not a number"),
    (b"digraph g {\n a -> {b c};\n}", 2, "subgraph"),
])
def test_dot_problems_name_their_line(text, line, words):
    result = check_dot_bytes(text, file="g.dot")
    assert not result.ok
    p = result.errors[0]
    assert p.line == line and words in str(p) and p.file == "g.dot"


@pytest.mark.parametrize("text,words", [
    (b'<?xml version="1.0"?><!DOCTYPE g [<!ENTITY a "aaaa">]><graphml><graph/></graphml>', "DTD"),
    (b"<graphml><graph edgedefault='undirected'></graph></graphml>", "undirected"),
    (b"<graphml><graph><edge source='a'/></graph></graphml>", "source or target"),
    (b"<graphml><graph>", "XML syntax error"),
    (b"<graphml></graphml>", "no <graph>"),
])
def test_graphml_problems_are_refused_cleanly(text, words):
    result = check_graphml_bytes(text, file="g.graphml")
    assert not result.ok and words in str(result.errors[0])


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_any_bytes_are_read_without_a_traceback(raw):
    for check in (check_dot_bytes, check_graphml_bytes):
        result = check(raw, file="f")
        assert result.plan is not None or result.errors


def test_networkx_round_trip_and_errors():
    nx = pytest.importorskip("networkx", reason="networkx is in the dev extra that make test installs")
    plan = load_plan(GEARBOX)
    g = plan.to_networkx()
    assert isinstance(g, nx.DiGraph) and g.nodes["co"]["name"] == "cover"
    same(plan, plan_from_networkx(g, name="gearbox"))
    cyc = nx.DiGraph([("a", "b"), ("b", "a")])
    with pytest.raises(PlanError, match="cycle"):
        plan_from_networkx(cyc)
    with pytest.raises(PlanError, match="undirected"):
        plan_from_networkx(nx.Graph([("a", "b")]))


@settings(max_examples=40, deadline=None)
@given(plan=random_plans(max_parts=7, max_units=9, max_strategies=1))
def test_networkx_round_trip(plan):
    """A plan of one strategy through a NetworkX DiGraph and back: the same parts and the same order."""
    pytest.importorskip("networkx", reason="networkx is in the dev extra that make test installs")
    same(plan, plan_from_networkx(plan.to_networkx(), name=plan.name))
