"""The sequencer and the opportunistic policy: Table 1, bad input, and properties against brute force."""

from __future__ import annotations

import json
import random
from collections import Counter as Tally
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import EXAMPLES, GEARBOX, brute_sequences, random_plans
from opportune import load_plan, make_plan
from opportune.formats.looks import LooksError, parse_looks, read_looks
from opportune.policies.base import Action
from opportune.sequencer import LookError, OutcomeError, Sequencer

TABLE1 = [  # Visible | Buffered | Installed | Action, from the paper
    ("rl,ra", "", "", "buffer rl"),
    ("ca,co", "rl", "", "install ca"),
    ("co,ml", "rl", "ca", "buffer ml"),
    ("st,dr", "rl,ml", "ca", "buffer dr"),
    ("cl,ba", "rl,ml,dr", "ca", "install ba"),
    ("cl,co", "rl,ml,dr", "ca,ba", "install rl"),
    ("cl,co", "ml,dr", "ca,ba,rl", "install dr"),
    ("cl,co", "ml", "ca,ba,rl,dr", "buffer co"),
    ("cl,sm", "ml,co", "ca,ba,rl,dr", "install sm"),
    ("cl,st", "ml,co", "ca,ba,rl,dr,sm", "install ml"),
    ("cl,st", "co", "ca,ba,rl,dr,sm,ml", "buffer cl"),
    ("ra,st", "co,cl", "ca,ba,rl,dr,sm,ml", "install ra"),
    ("st", "co,cl", "ca,ba,rl,dr,sm,ml,ra", "install co"),
    ("st", "cl", "ca,ba,rl,dr,sm,ml,ra,co", "install st"),
    ("", "cl", "ca,ba,rl,dr,sm,ml,ra,co,st", "install cl"),
]


def split(text):
    return tuple(p for p in text.split(",") if p)


def test_table1_is_reproduced():
    seq = Sequencer(load_plan(GEARBOX))
    looks = read_looks(EXAMPLES / "gearbox-table1.looks")
    assert [",".join(look) for look in looks] == [row[0] for row in TABLE1]
    for look, (visible, buffered, installed, action) in zip(looks, TABLE1):
        assert seq.state.buffer == split(buffered)
        assert seq.state.installed == split(installed)
        decision = seq.step(look)
        kind, part = action.split()
        assert (decision.action.kind, decision.action.part) == (kind, part), (visible, decision.explain())
    assert seq.state.is_complete
    assert seq.state.installed == ("ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl")
    # Buffered parts are installed from the buffer.
    sources = {row.action.part: row.action.source for row in seq.trace if row.action.kind == "install"}
    assert sources["rl"] == sources["dr"] == sources["ml"] == sources["co"] == sources["cl"] == "buffer"
    assert sources["ca"] == sources["ba"] == sources["sm"] == sources["ra"] == "bin"


def test_table1_replay_cli():
    from typer.testing import CliRunner

    from opportune.cli import app

    r = CliRunner().invoke(app, ["replay", str(GEARBOX), str(EXAMPLES / "gearbox-table1.looks"), "--json"])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    assert len(rows) == 16
    for row, (visible, buffered, installed, action) in zip(rows, TABLE1):
        assert row["visible"] == list(split(visible))
        assert row["buffered"] == list(split(buffered))
        assert row["installed"] == list(split(installed))
        kind, part = action.split()
        assert row["action"]["kind"] == kind and row["action"]["part"] == part
        assert row["action"]["source"] == ("buffer" if kind == "install" and part in row["buffered"] and part not in row["visible"]
                                           else "bin" if kind == "install" else None)
    assert rows[-1]["action"] == {"kind": "done", "part": None, "source": None}
    assert rows[-1]["installed"] == ["ca", "ba", "rl", "dr", "sm", "ml", "ra", "co", "st", "cl"]
    table = CliRunner().invoke(app, ["replay", str(GEARBOX), str(EXAMPLES / "gearbox-table1.looks")]).output
    assert "Visible" in table and "buffer rl" in table and "install cl" in table
    explained = CliRunner().invoke(app, ["replay", str(GEARBOX), str(EXAMPLES / "gearbox-table1.looks"),
                                         "--explain"]).output
    assert "expected position" in explained and "keeps" in explained


def test_decisions_carry_their_reasons():
    seq = Sequencer(load_plan(GEARBOX))
    d = seq.decide(["rl", "ra"])
    assert d.action == Action("buffer", "rl")
    positions = dict(d.positions)
    assert positions["rl"] == positions["ra"]  # a tie, broken by declaration order (rl before ra)
    assert "expected position" in d.explain()
    seq.report("success")
    d = seq.decide(["ca", "co"])
    assert d.candidates[0].part == "ca" and d.candidates[0].options == d.candidates[0].total == 336


# ---------------------------------------------------------------- bad input: clear error, no state change


@pytest.fixture
def seq():
    s = Sequencer(load_plan(GEARBOX))
    s.step(["rl", "ra"])  # buffer rl
    s.step(["ca", "co"])  # install ca
    return s


def snapshot(s):
    return (s.state, s.pending, len(s.trace))


@pytest.mark.parametrize("look, message", [
    (["zz"], "unknown part 'zz'"),
    (["ca"], "'ca' is already installed"),
    (["rl"], "'rl' is in a buffer location"),
    (["ba", "ba"], "shows 2 of part 'ba' but only 1"),
    ("ba", "not a single string"),
    ([3], "part ids are strings"),
])
def test_bad_looks_are_refused_without_state_change(seq, look, message):
    before = snapshot(seq)
    with pytest.raises(LookError, match=message):
        seq.decide(look)
    assert snapshot(seq) == before


def test_outcome_without_a_decision(seq):
    before = snapshot(seq)
    with pytest.raises(OutcomeError, match="no action is pending"):
        seq.report("success")
    assert snapshot(seq) == before


def test_look_while_an_action_is_pending(seq):
    seq.decide(["ba"])
    before = snapshot(seq)
    with pytest.raises(LookError, match="pending"):
        seq.decide(["ba"])
    with pytest.raises(OutcomeError, match="unknown outcome"):
        seq.report("exploded")
    assert snapshot(seq) == before


def test_look_after_the_assembly_is_complete():
    plan = make_plan(["a", "b"], {"b": ["a"]})
    s = Sequencer(plan)
    s.step(["a"])
    s.step(["b"])
    with pytest.raises(LookError, match="complete"):
        s.decide(["a"])
    assert s.decide([]).action.kind == "done"
    with pytest.raises(LookError, match="complete"):
        s.decide([])


def test_malformed_looks_files(tmp_path):
    with pytest.raises(LooksError, match="must stand alone"):
        parse_looks("a - b\n", file="x.looks")
    with pytest.raises(LooksError, match="JSON syntax error"):
        parse_looks("[[\"a\"],\n", file="x.json")
    with pytest.raises(LooksError, match="list of lists"):
        parse_looks('["a", "b"]')
    with pytest.raises(LooksError, match="no such file"):
        read_looks(tmp_path / "none.looks")
    assert parse_looks("# c\na, b # x\n\n-\n") == [("a", "b"), ()]
    assert parse_looks('[["a","b"],[]]') == [("a", "b"), ()]


def test_replay_reports_bad_look_with_its_number(tmp_path):
    from typer.testing import CliRunner

    from opportune.cli import app

    looks = tmp_path / "bad.looks"
    looks.write_text("rl ra\nca ca\n")
    r = CliRunner().invoke(app, ["replay", str(GEARBOX), str(looks)])
    assert r.exit_code == 1 and "look 2" in r.output and "only 1" in r.output and "Traceback" not in r.output


# ---------------------------------------------------------------- outcomes


def test_failed_install_back_to_bin_or_buffer():
    plan = load_plan(GEARBOX)
    s = Sequencer(plan)
    s.decide(["ca"])
    s.report("failed")  # back to the bin
    assert s.state.installed == () and s.state.in_bin["ca"] == 1
    s.decide(["ca"])
    s.report("failed", keep="buffer")  # kept in the gripper, buffered
    assert s.state.buffer == ("ca",)
    d = s.decide([])
    assert d.action == Action("install", "ca", "buffer")
    s.report("success")
    assert s.state.installed == ("ca",) and s.state.buffer == ()


def test_defective_part_waits_for_a_replacement():
    s = Sequencer(load_plan(GEARBOX))
    s.decide(["ca"])
    s.report("defective")
    assert s.state.installed == () and s.state.defects == 1 and s.state.in_bin["ca"] == 1
    assert s.decide(["ca"]).action == Action("install", "ca", "bin")


def test_cancel_drops_the_pending_action():
    s = Sequencer(load_plan(GEARBOX))
    s.decide(["ca"])
    s.cancel()
    assert s.pending is None and s.state.installed == ()


def test_finite_buffer_shakes_when_full():
    s = Sequencer(load_plan(GEARBOX), buffer_capacity=1)
    assert s.step(["rl"]).action == Action("buffer", "rl")
    assert s.step(["dr"]).action.kind == "shake"


# ---------------------------------------------------------------- properties


def brute_decision(plan, installed, buffer, visible, capacity):
    """The opportunistic rule computed by enumerating every admissible completion."""
    completions = brute_sequences(plan, installed)
    if not completions or not completions[0]:
        return ("done", None, None)
    firsts = Tally(c[0] for c in completions)
    cands = []
    for part in dict.fromkeys(visible):
        if part in firsts:
            cands.append((part, "bin", None))
    for pos, part in enumerate(buffer):
        if part in firsts and part not in [c[0] for c in cands if c[1] == "buffer"]:
            cands.append((part, "buffer", pos))
    if cands:
        cands.sort(key=lambda c: (-firsts[c[0]], c[1] != "bin", plan.part(c[0]).cost,
                                  -1 if c[2] is None else c[2], plan.index(c[0])))
        return ("install", cands[0][0], cands[0][1])
    if visible and (capacity is None or len(buffer) < capacity):
        pos = {p: Fraction(sum(c.index(p) + 1 for c in completions), len(completions)) for p in set(visible)}
        return ("buffer", min(pos, key=lambda p: (pos[p], plan.index(p))), None)
    return ("shake", None, None)


@st.composite
def runs(draw):
    plan = draw(random_plans(max_parts=5, max_units=6, max_strategies=2))
    capacity = draw(st.sampled_from([None, 0, 1, 2]))
    seed = draw(st.integers(0, 2**32))
    return plan, capacity, seed


@settings(max_examples=120, deadline=None)
@given(runs())
def test_policy_follows_the_rules_and_completes(case):
    plan, capacity, seed = case
    rng = random.Random(seed)
    s = Sequencer(plan, buffer_capacity=capacity)
    admissible = set(brute_sequences(plan))
    for _ in range(400):
        if s.state.is_complete:
            break
        bin_units = [p for p, n in s.state.in_bin.items() for _ in range(n)]
        k = rng.randint(0 if rng.random() < 0.2 else 1, min(3, len(bin_units))) if bin_units else 0
        look = tuple(rng.sample(bin_units, k))
        expected = brute_decision(plan, s.state.installed, s.state.buffer, look, capacity)
        d = s.decide(look)
        assert (d.action.kind, d.action.part, d.action.source) == expected
        if d.action.kind == "buffer":
            # Nothing is buffered while a visible or buffered part could be installed.
            assert not any(s.state.schedule.can_install(p) for p in set(look) | set(s.state.buffer))
        s.report("success")
        # Every install respects some consistent strategy: the installed prefix extends to an admissible sequence.
        assert any(seq[:len(s.state.installed)] == s.state.installed for seq in admissible)
    if capacity is None:
        assert s.state.is_complete  # every part eventually shows
    if s.state.is_complete:
        assert s.state.installed in admissible
        assert s.state.buffer == ()
