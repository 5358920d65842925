"""Learning a plan from observed sequences (issue 15, part 4): against brute force on random small plans."""

from __future__ import annotations

import doctest
import json
import random
from fractions import Fraction

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from conftest import brute_sequences, multiset_permutations, random_plans, run_cli, spans
from opportune.engine import NotAdmissible, Schedule
from opportune.engine.poset import Poset
from opportune.formats import load_plan, plan_from_dict
from opportune.formats import sequences as seqfmt
from opportune.formats.sequences import SequenceError, parse_sequences, read_sequences
from opportune.derive.learn import learn_plan, learned_order

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ---------------------------------------------------------------- brute-force references


def before(seq, a, b) -> bool:
    """Every unit of a before every unit of b (what a constraint a -> b asks)."""
    return max(i for i, p in enumerate(seq) if p == a) < min(i for i, p in enumerate(seq) if p == b)


def closure(plan) -> set[tuple[str, str]]:
    """The plan's (single strategy's) order, transitively closed, as (before, after) id pairs."""
    ids = plan.part_ids
    poset = Poset.from_pairs(len(ids), plan.index_pairs(plan.strategies[0]))
    return {(ids[a], ids[b]) for a in range(len(ids)) for b in range(len(ids)) if poset.less(a, b)}


def intersection(seqs, ids) -> set[tuple[str, str]]:
    return {(a, b) for a in ids for b in ids if a != b and all(before(s, a, b) for s in seqs)}


def admits(plan, seq) -> bool:
    """The engine's word on whether the plan admits the complete sequence."""
    try:
        return Schedule(plan, seq).is_complete
    except NotAdmissible:
        return False


one_strategy = random_plans(max_parts=7, max_units=8, max_strategies=1)


# ---------------------------------------------------------------- learning


@FAST
@given(one_strategy)
def test_all_sequences_recover_the_generating_plan(plan):
    seqs = brute_sequences(plan)
    learned = learn_plan(seqs, time_limit=None)
    assert closure(learned.plan) == closure(plan)
    assert {p.id: p.quantity for p in learned.plan.parts} == {p.id: p.quantity for p in plan.parts}
    # the plan is written as its cover relations: nothing declared is implied by the rest
    ids = learned.plan.part_ids
    declared = set(learned.plan.index_pairs(learned.plan.strategies[0]))
    assert declared == set(Poset.from_pairs(len(ids), declared).cover_pairs())
    assert learned.sequences == len(seqs) == learned.distinct


@FAST
@given(one_strategy, st.data())
def test_learning_from_a_subset_never_forbids_an_observed_sequence(plan, data):
    everything = brute_sequences(plan)
    seqs = data.draw(st.lists(st.sampled_from(everything), min_size=1, max_size=12))
    learned = learn_plan(seqs, time_limit=None)
    for seq in seqs:
        assert admits(learned.plan, seq)
    # the learned order is exactly what every observed sequence satisfies (least constrained)...
    assert closure(learned.plan) == intersection(seqs, plan.part_ids)
    # ...so it contains the generating plan's order
    assert closure(plan) <= closure(learned.plan)
    # and it admits exactly the sequences that satisfy that intersection
    admitted = {s for s in everything if admits(learned.plan, s)}
    assert set(seqs) <= admitted


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(one_strategy, st.data())
def test_accident_probability_is_the_brute_force_fraction_to_the_n(plan, data):
    everything = brute_sequences(plan)
    seqs = data.draw(st.lists(st.sampled_from(everything), min_size=1, max_size=6))
    learned = learn_plan(seqs, time_limit=None)
    units = [p.id for p in learned.plan.parts for _ in range(p.quantity)]
    # every ordering of the units, with its parts' first and last positions (`before` on them), once
    every = [spans(s) for s in multiset_permutations(units)]
    for c in learned.constraints:
        # the learned order without this one relation (every other relation kept), by brute force
        relaxed = closure(learned.plan) - {(c.before, c.after)}
        ok = [(first, last) for first, last in every if all(last[a] < first[b] for a, b in relaxed)]
        p = Fraction(sum(last[c.before] < first[c.after] for first, last in ok), len(ok))
        assert c.support == len(seqs)
        assert 0 <= c.accident_probability <= 1 and 0 < c.chance < 1
        assert c.chance == pytest.approx(float(p), rel=1e-12)
        assert c.accident_probability == pytest.approx(float(p ** len(seqs)), rel=1e-9, abs=1e-300)


def test_accident_probability_on_a_chain_of_one_observation():
    # one sequence a b c: the learned plan is the chain; without a -> b (a -> c kept), a and b are free
    learned = learn_plan(["a b c"])
    assert [(c.before, c.after, c.chance, c.accident_probability) for c in learned.constraints] == [
        ("a", "b", 0.5, 0.5), ("b", "c", 0.5, 0.5)]
    assert len(learned.flagged) == 2
    assert learn_plan(["a b c"] * 5).constraints[0].accident_probability == pytest.approx(1 / 32)


def test_units_of_a_part_repeat_its_id():
    learned = learn_plan(["s s a b", "s a s b"])
    assert {p.id: p.quantity for p in learned.plan.parts} == {"s": 2, "a": 1, "b": 1}
    assert closure(learned.plan) == {("s", "b"), ("a", "b")}     # s's last unit is not always before a
    with pytest.raises(SequenceError, match="appears once, in the first sequence .* twice"):
        learn_plan(["s s a", "s a"])


def test_learned_order_is_the_intersection_on_random_permutations():
    rng = random.Random(4)
    ids = [f"p{i}" for i in range(6)]
    for _ in range(50):
        seqs = [tuple(rng.sample(ids, len(ids))) for _ in range(rng.randint(1, 4))]
        order = learned_order(seqs, ids)
        got = {(ids[a], ids[b]) for a in range(6) for b in range(6) if order.less(a, b)}
        assert got == intersection(seqs, ids)


def test_counting_over_budget_leaves_the_plan_right_and_says_so():
    learned = learn_plan(["a b c", "b a c"], time_limit=0)
    assert not learned.complete and all(c.accident_probability is None for c in learned.constraints)
    assert closure(learned.plan) == {("a", "c"), ("b", "c")}
    assert "not computed" in learned.to_yaml()


# ---------------------------------------------------------------- failed sequences


@FAST
@given(one_strategy, st.data())
def test_failed_sequences_are_reported_against_brute_force(plan, data):
    everything = brute_sequences(plan)
    seqs = data.draw(st.lists(st.sampled_from(everything), min_size=1, max_size=6))
    units = [p.id for p in plan.parts for _ in range(p.quantity)]
    every = list(multiset_permutations(units))
    failed = data.draw(st.lists(st.sampled_from(every), max_size=4))
    learned = learn_plan(seqs, failed, time_limit=None)
    covers = [(c.before, c.after) for c in learned.constraints]
    for f, report in zip(failed, learned.failed):
        assert set(report.violates) == {(a, b) for a, b in covers if not before(f, a, b)}
        assert report.excluded == (not admits(learned.plan, f))
        assert report.succeeded == (f in seqs)
    for c in learned.constraints:
        assert c.confirmed == any((c.before, c.after) in r.violates for r in learned.failed)
    open_ = [f for f, r in zip(failed, learned.failed) if not r.excluded]
    assert [r.sequence for r in learned.unexcluded] == open_
    if learned.repair is not None:
        assert open_ and len(learned.repair.strategies) == 2
        for s in seqs:
            assert admits(learned.repair, s)
        for f in failed:
            assert not admits(learned.repair, f)
    elif open_:
        assert learned.repair_note


def test_an_unexcludable_failure_is_reported_and_repaired_by_two_strategies(tmp_path):
    # every single order admitting both successes has a, b before c, d: it admits a b d c too
    (tmp_path / "ok.seq").write_text("a b c d\nb a d c\n")
    (tmp_path / "bad.seq").write_text("# failed\na b d c\n")
    result = run_cli("learn", tmp_path / "ok.seq", "--failed", tmp_path / "bad.seq", "--json")
    assert result.exit_code == 0
    doc = json.loads(result.stdout)
    assert doc["unexcluded"] == [f"{tmp_path / 'bad.seq'}:2"]
    assert doc["failed"][0]["excluded"] is False and doc["repair"] is not None
    assert "cannot be excluded" in result.stderr
    written = run_cli("learn", tmp_path / "ok.seq", "--failed", tmp_path / "bad.seq", "--split",
                      "-o", tmp_path / "two.yaml")
    assert written.exit_code == 0
    two = load_plan(tmp_path / "two.yaml")
    assert len(two.strategies) == 2 and not admits(two, ("a", "b", "d", "c"))
    assert admits(two, ("a", "b", "c", "d")) and admits(two, ("b", "a", "d", "c"))


def test_a_failure_that_also_succeeded_cannot_be_repaired():
    learned = learn_plan(["a b", "b a"], ["a b"])
    assert learned.unexcluded[0].succeeded and learned.repair is None
    assert "also among the successes" in learned.repair_note


# ---------------------------------------------------------------- the command


def test_learn_the_shipped_gearbox_observations(tmp_path):
    result = run_cli("learn", "example:gearbox-observed", "--failed", "example:gearbox-failed", "-o",
                     tmp_path / "learned.yaml")
    assert result.exit_code == 0, result.output
    text = (tmp_path / "learned.yaml").read_text()
    assert "# support 12/12, accident" in text and "confirmed by a failure" in text
    plan = load_plan(tmp_path / "learned.yaml")
    gearbox = load_plan(seqfmt._example("gearbox-observed").with_name("gearbox.yaml"))
    assert closure(plan) == closure(gearbox)       # twelve sequences happen to recover the gearbox
    assert "example:gearbox-failed:2: failed sequence breaks ra -> co (confirmed)" in result.stderr
    assert "may be accidents" in result.stderr


def test_learn_json_document():
    result = run_cli("learn", "example:gearbox-observed", "--json", "--name", "gb", "--max-accident", "0.2")
    doc = json.loads(result.stdout)
    assert doc["sequences"] == 12 and doc["plan"]["name"] == "gb"
    assert plan_from_dict(doc["plan"]).part_ids[0] == "ca"
    cons = doc["constraints"]
    assert {(c["before"], c["after"]) for c in cons} == {
        (b, a) for a, bs in doc["plan"]["strategies"][0]["requires"].items() for b in bs}
    assert all(0 <= c["accident_probability"] <= 1 and c["support"] == 12 for c in cons)
    assert [c["flagged"] for c in cons] == [c["accident_probability"] > 0.2 for c in cons]


def test_learn_reads_standard_input_and_writes_yaml_that_loads(tmp_path):
    from typer.testing import CliRunner

    from opportune.cli import app

    result = CliRunner().invoke(app, ["learn", "-"], input="x y z\nx, z, y  # commas\n\n")
    assert result.exit_code == 0
    path = tmp_path / "p.yaml"
    path.write_text(result.stdout)
    assert closure(load_plan(path)) == {("x", "y"), ("x", "z")}


@pytest.mark.parametrize("text, line, message", [
    ("a b c\na b d\n", 2, "unknown part 'd'"),
    ("a b c\n# note\na b\n", 3, "part 'c' is missing"),
    ("a b c\na b c c\n", 2, "part 'c' appears twice"),
    ("a a b\na b\n", 2, "part 'a' appears once"),
])
def test_bad_lines_are_named_with_file_and_line(tmp_path, text, line, message):
    path = tmp_path / "s.seq"
    path.write_text(text)
    result = run_cli("learn", path)
    assert result.exit_code == 1
    assert f"{path}:{line}: error: {message}" in result.stderr
    doc = json.loads(run_cli("learn", path, "--json").stdout)["error"]
    assert doc["line"] == line and doc["file"] == str(path)


def test_other_bad_input(tmp_path):
    empty = tmp_path / "empty.seq"
    empty.write_text("# nothing\n\n")
    assert "no sequences to learn from" in run_cli("learn", empty).stderr
    assert "no such file" in run_cli("learn", tmp_path / "missing.seq").stderr
    assert "no example sequences named 'nope'" in run_cli("learn", "example:nope").stderr
    assert "no example sequences" in run_cli("learn", "example:../gearbox").stderr
    (tmp_path / "latin.seq").write_bytes(b"a b\n\xe9 a\n")
    assert f"{tmp_path / 'latin.seq'}:2: error: not UTF-8" in run_cli("learn", tmp_path / "latin.seq").stderr
    ok = tmp_path / "ok.seq"
    ok.write_text("a b\n")
    bad = tmp_path / "bad.seq"
    bad.write_text("a c\n")
    out = run_cli("learn", ok, "--failed", bad)
    assert out.exit_code == 1 and f"{bad}:1: error: unknown part 'c'" in out.stderr
    assert run_cli("learn", "-", "--failed", "-").exit_code == 2
    assert run_cli("learn", ok, "--max-accident", "2").exit_code == 2
    assert run_cli("learn", ok, "-o", tmp_path / "no" / "dir.yaml").exit_code == 1


def test_bounds_are_refused_with_a_message(tmp_path):
    many = tmp_path / "many.seq"
    many.write_text("a b\n" * (seqfmt.MAX_SEQUENCES + 1))
    result = run_cli("learn", many)
    assert result.exit_code == 1 and f"more than {seqfmt.MAX_SEQUENCES:,} sequences" in result.stderr
    long = tmp_path / "long.seq"
    long.write_text(" ".join(f"p{i}" for i in range(10_001)) + "\n")
    assert "10,001 installations in one sequence; at most 10,000" in run_cli("learn", long).stderr
    big = tmp_path / "big.seq"
    with big.open("wb") as f:
        f.truncate(seqfmt.MAX_SEQUENCE_BYTES + 1)
    assert f"larger than {seqfmt.MAX_SEQUENCE_BYTES:,} bytes" in run_cli("learn", big).stderr


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=300))
def test_hostile_bytes_give_a_sequence_error_or_a_plan(raw):
    try:
        seqs = seqfmt.parse_sequences(raw.decode("utf-8", "surrogateescape"), file="fuzz")
        learned = learn_plan(seqs, time_limit=1)
    except SequenceError as exc:
        assert exc.problem.file == "fuzz" and str(exc)
        return
    assert all(admits(learned.plan, s) for s in seqs.sequences)


id_text = st.text(st.characters(blacklist_categories=("Cs", "Cc"), blacklist_characters=" ,#\t\n\r\x0b\x0c\x1c\x1d\x1e"
                                "\x1f\x85\xa0\u1680\u2028\u2029\u3000\u2000\u2001\u2002\u2003\u2004\u2005\u2006"
                                "\u2007\u2008\u2009\u200a\u202f\u205f"), min_size=1, max_size=6)


@settings(max_examples=60, deadline=None)
@given(st.lists(id_text, min_size=1, max_size=4, unique=True), st.randoms(use_true_random=False))
def test_the_yaml_round_trips_any_part_ids(tmp_path_factory, ids, rnd):
    ids = [i for i in ids if i.split() == [i]]  # ids are what splitting a line gives
    if not ids:
        return
    seqs = [ids, rnd.sample(ids, len(ids))]
    text = "\n".join(" ".join(s) for s in seqs) + "\n"
    try:
        parsed = parse_sequences(text)
    except SequenceError:
        return
    learned = learn_plan(parsed, name="weird: {name}")
    path = tmp_path_factory.mktemp("yaml") / "p.yaml"
    path.write_text(learned.to_yaml(), encoding="utf-8")
    back = load_plan(path)
    assert back.part_ids == learned.plan.part_ids and back.name == "weird: {name}"
    assert closure(back) == closure(learned.plan)


def test_docstring_examples():
    from opportune.derive import learn
    from opportune.formats import sequences

    for module in (learn, sequences):
        assert doctest.testmod(module).failed == 0


def test_read_sequences_takes_text_paths_and_examples(tmp_path):
    assert read_sequences("a b\nb a\n").sequences == (("a", "b"), ("b", "a"))
    path = tmp_path / "x.seq"
    path.write_text("a b\n")
    assert read_sequences(path).file == str(path) and read_sequences(str(path)).lines == (1,)
    assert read_sequences("example:gearbox-observed").file == "example:gearbox-observed"


def test_the_repair_search_is_bounded(monkeypatch):
    from opportune.derive import learn

    monkeypatch.setattr(learn, "MAX_REPAIR_WORK", 10)
    learned = learn_plan(["a b c d", "b a d c"], ["a b d c"])
    assert learned.repair is None and "stopped after 10 mask operations" in learned.repair_note
    monkeypatch.undo()
    assert learn_plan(["a b c d", "b a d c"], ["a b d c"]).repair is not None
