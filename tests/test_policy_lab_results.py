"""The policy lab's results file: how its lines are read back (benchmarks/policy_lab.py)."""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import policy_lab  # noqa: E402

KEY = "0:8-12:r1-12:2:inf:pile:"


def _read(lines, cap=2_000_000):
    done: dict = {}
    for key, rec in lines:
        policy_lab._keep(done, key, dict(rec), cap)
    return done


def test_an_exact_result_stands_whatever_cap_it_ran_with():
    done = _read([(KEY + "2000000", {"skipped": "too many states"}),
                  (KEY + "3000000", {"gaps": {"lookahead": 0.0}, "optimum": 21.5, "states": 2_500_000})])
    assert done == {KEY + "2000000": {"gaps": {"lookahead": 0.0}, "optimum": 21.5, "states": 2_500_000}}


def test_a_skip_never_hides_a_result_and_skips_at_other_caps_stay_apart():
    done = _read([(KEY + "2000000", {"gaps": {"paper": 0.01}, "optimum": 2.0, "states": 9}),
                  (KEY + "2000000", {"skipped": "took too long"}),
                  (KEY + "3000000", {"skipped": "too many states"})])
    assert done[KEY + "2000000"]["gaps"] == {"paper": 0.01}
    assert done[KEY + "3000000"] == {"skipped": "too many states"}


def test_a_later_rerun_of_one_policy_keeps_the_others_gaps():
    done = _read([(KEY + "2000000", {"gaps": {"paper": 0.01, "lookahead": 0.01}, "optimum": 2.0, "states": 9}),
                  (KEY + "2000000", {"gaps": {"lookahead": 0.0}, "optimum": 2.0, "states": 9})])
    assert done[KEY + "2000000"]["gaps"] == {"paper": 0.01, "lookahead": 0.0}


# ------------------------------------------------------------------ the committed results and what is written from them

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "policy_lab_results.jsonl"


def _committed():
    """The lab's jobs as the committed documents were written (``--no-run``) and the results read back."""
    args = policy_lab._args(["--no-run", "--results", str(RESULTS), "--paired", ""])
    jobs, groups = policy_lab.make_jobs(args)
    done = policy_lab.read_results(RESULTS, args.max_states)
    return args, jobs, groups, policy_lab.cells(jobs, done)


def test_the_docs_table_and_the_readme_claim_are_written_from_the_committed_results():
    args, _, groups, table = _committed()
    names = list(policy_lab.TABLE_POLICIES)
    cpu = sum(sum(r.get("cpu", {}).values()) for c in table.values() for r in c.rows)
    assert (ROOT / "docs" / "policy-lab.md").read_text() == policy_lab.document(table, groups, names, args.plans, cpu)
    assert policy_lab.read_block(ROOT / "README.md") == policy_lab.readme_block(table, groups, args.settings, args)


def _lines():
    return [json.loads(line) for line in RESULTS.read_text().splitlines() if line.strip()]


def test_no_policy_beats_the_optimum_in_the_committed_results():
    """Every gap of every line is at least the optimum's (a policy below it would be a wrong optimum)."""
    lines = _lines()
    assert len(lines) > 1000
    for rec in lines:
        for name, gap in rec.get("gaps", {}).items():
            assert gap >= -1e-9, (rec["key"], name, gap)


def test_the_readme_numbers_are_the_results_counted_directly():
    """A second count, from the raw lines (the last line of a plan-setting's policy wins): per size, the
    default's worst setting's mean and its largest gap, and the plan-settings, as the README's rows say."""
    gaps: dict[tuple, dict[str, float]] = {}        # (size, setting) -> plan -> the default's gap
    solved: set[tuple] = set()                      # (size, setting, plan) with the optimum
    for rec in _lines():
        seed, group, plan, visible, cap, bin, _ = rec["key"].split(":")
        if seed != "0" or "-" not in group or plan == "gearbox" or "optimum" not in rec:
            continue
        solved.add((group, visible, cap, bin, plan))
        if "lookahead" in rec["gaps"]:
            gaps.setdefault((group, visible, cap, bin), {})[plan] = rec["gaps"]["lookahead"]
    readme = (ROOT / "README.md").read_text()
    for size in ("8-12", "16", "20", "25", "30"):
        lo, _, hi = size.partition("-")
        cells = [v for k, v in gaps.items() if k[0] == f"{lo}-{hi or lo}"]
        assert cells, size
        worst = max(sum(c.values()) / len(c) for c in cells)
        top = max(max(c.values()) for c in cells)
        label = size.replace("-", "–")
        row = next(line for line in readme.splitlines() if line.startswith(f"| {label} |"))
        fields = [f.strip() for f in row.split("|")]
        assert int(fields[3]) == sum(1 for k in solved if k[0] == f"{lo}-{hi or lo}"), (size, row)
        assert fields[5:7] == [_pct(worst), _pct(top)], (size, row)


def _pct(x: float) -> str:
    v = 100 * x
    return f"{0.0 if abs(v) < 5e-4 else v:+.3f}%"


def test_a_gap_of_another_version_of_its_policy_is_stale():
    """A policy's gaps measured at another version (POLICY_VERSIONS) are dropped, so that rerunning that
    policy alone recomputes them; a line without versions measured UNTAGGED's."""
    now = policy_lab.POLICY_VERSIONS["fallback"]
    done = _read([(KEY + "2000000", {"gaps": {"paper": 0.01, "fallback": 0.02}, "optimum": 2.0, "states": 9})])
    assert done[KEY + "2000000"]["gaps"] == ({"paper": 0.01, "fallback": 0.02} if policy_lab.UNTAGGED["fallback"] == now
                                            else {"paper": 0.01})
    done = _read([(KEY + "2000000", {"gaps": {"paper": 0.01, "fallback": 0.02}, "optimum": 2.0, "states": 9,
                                     "versions": {"fallback": now + " (older)"}})])
    assert done[KEY + "2000000"]["gaps"] == {"paper": 0.01}
    assert policy_lab._missing(done[KEY + "2000000"], ("fallback", "paper"), False) == ("fallback",)


def test_a_bin_whose_fallback_changed_alone_has_its_own_version():
    """The pile's fallback became the pile's own window while the uniform bin's stayed: a pile row tagged with
    the uniform bin's version is stale (rerun), a uniform row of that version is not."""
    now = policy_lab.POLICY_VERSIONS["fallback"]
    assert policy_lab.policy_version("fallback", "pile") != now == policy_lab.policy_version("fallback", "uniform")
    line = {"gaps": {"paper": 0.01, "fallback": 0.02}, "optimum": 2.0, "states": 9, "versions": {"fallback": now}}
    done = _read([(KEY + "2000000", {**line, "bin": "pile"}),
                  ("0:8-12:r1-12:2:inf:uniform:2000000", {**line, "bin": "uniform"})])
    assert done[KEY + "2000000"]["gaps"] == {"paper": 0.01}
    assert done["0:8-12:r1-12:2:inf:uniform:2000000"]["gaps"] == {"paper": 0.01, "fallback": 0.02}
    pile = {**line, "bin": "pile", "versions": {"fallback": policy_lab.policy_version("fallback", "pile")}}
    assert _read([(KEY + "2000000", pile)])[KEY + "2000000"]["gaps"] == {"paper": 0.01, "fallback": 0.02}


def test_rerunning_one_policy_runs_that_policy_alone_and_keeps_the_others(tmp_path, monkeypatch):
    """``--policies fallback`` after a new version of the fallback: one new line with its gap alone, the
    paper's rule's gap kept from the old line."""
    out = tmp_path / "lab.jsonl"
    argv = ["--sizes", "7", "--plans", "1", "--salbp", "", "--only", "r0-7", "--bins", "uniform", "--visible", "1",
            "--capacities", "1", "--paired", "", "--results", str(out)]
    assert policy_lab.main(argv + ["--policies", "paper,fallback"]) == 0
    first = _lines_of(out)
    assert [sorted(r["gaps"]) for r in first] == [["fallback", "paper"]]
    assert policy_lab.main(argv + ["--policies", "fallback"]) == 0
    assert len(_lines_of(out)) == 1                 # nothing missing: nothing run
    monkeypatch.setitem(policy_lab.POLICY_VERSIONS, "fallback", "a new fallback")
    assert policy_lab.main(argv + ["--policies", "paper,fallback"]) == 0
    lines = _lines_of(out)
    assert len(lines) == 2 and list(lines[1]["gaps"]) == ["fallback"]
    assert lines[1]["versions"] == {"fallback": "a new fallback"} and lines[1]["cpu"].keys() == {"optimum", "fallback"}
    done = policy_lab.read_results(out, 2_000_000)
    (rec,) = done.values()
    assert rec["gaps"] == {"paper": first[0]["gaps"]["paper"], "fallback": lines[1]["gaps"]["fallback"]}


def _lines_of(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_a_plan_over_the_state_cap_is_skipped_with_its_count_before_any_work():
    plan = policy_lab.random_plan(policy_lab.random.Random(1), 14, 1, 0.05)
    r = policy_lab.measure(plan, 2, None, max_states=1000)
    assert r["skipped"].startswith("optimum over 1,000 states: ") and r["estimate"] > 1000
    assert "cpu" not in r


def test_a_policys_gap_on_a_one_strategy_plan_stays_current_at_a_version_that_decides_the_same_there(monkeypatch):
    """A new fallback that changes decisions on plans of several strategies only: its older gaps on
    one-strategy plans count, those on two-strategy plans do not."""
    monkeypatch.setitem(policy_lab.POLICY_VERSIONS, "fallback", "new")
    monkeypatch.setitem(policy_lab.SAME_ON_ONE_STRATEGY, "fallback", ("old",))
    one = {"gaps": {"fallback": 0.01, "paper": 0.1}, "versions": {"fallback": "old"}, "two_strategies": False}
    two = {**one, "two_strategies": True}
    older = {**one, "versions": {"fallback": "older"}}
    assert policy_lab._fresh(one)["gaps"] == {"fallback": 0.01, "paper": 0.1}
    assert policy_lab._fresh(two)["gaps"] == {"paper": 0.1}
    assert policy_lab._fresh(older)["gaps"] == {"paper": 0.1}


def test_a_bins_own_version_keeps_its_own_one_strategy_gaps_only(monkeypatch):
    """In a bin with a version of its own, only that bin's earlier versions that decide the same on
    one-strategy plans keep their gaps there; the bin-less list does not reach it."""
    monkeypatch.setitem(policy_lab.BIN_VERSIONS, ("fallback", "pile"), "new")
    monkeypatch.setitem(policy_lab.BIN_SAME_ON_ONE_STRATEGY, ("fallback", "pile"), ("old pile",))
    monkeypatch.setitem(policy_lab.SAME_ON_ONE_STRATEGY, "fallback", ("old uniform",))
    one = {"gaps": {"fallback": 0.01}, "versions": {"fallback": "old pile"}, "two_strategies": False, "bin": "pile"}
    assert policy_lab._fresh(one)["gaps"] == {"fallback": 0.01}
    assert policy_lab._fresh({**one, "two_strategies": True})["gaps"] == {}
    assert policy_lab._fresh({**one, "versions": {"fallback": "old uniform"}})["gaps"] == {}
    assert policy_lab._fresh({**one, "versions": {"fallback": "new"}, "two_strategies": True})["gaps"] == {"fallback": 0.01}


def test_a_change_of_one_strategys_decisions_keeps_the_gaps_of_several_and_of_settings_it_did_not_touch(monkeypatch):
    """A new fallback deciding otherwise on one-strategy plans alone: the older gaps on two-strategy plans
    count (SAME_ON_SEVERAL_STRATEGIES), those on one-strategy plans do not; in a bin with a version of its own,
    an older version counts in the settings BIN_SAME_AT names and nowhere else."""
    monkeypatch.setitem(policy_lab.POLICY_VERSIONS, "fallback", "new")
    monkeypatch.setitem(policy_lab.SAME_ON_SEVERAL_STRATEGIES, "fallback", ("old",))
    monkeypatch.setitem(policy_lab.SAME_ON_ONE_STRATEGY, "fallback", ())
    two = {"gaps": {"fallback": 0.01}, "versions": {"fallback": "old"}, "two_strategies": True, "bin": "uniform"}
    assert policy_lab._fresh(two)["gaps"] == {"fallback": 0.01}
    assert policy_lab._fresh({**two, "two_strategies": False})["gaps"] == {}
    assert policy_lab._fresh({**two, "versions": {"fallback": "older"}})["gaps"] == {}
    monkeypatch.setitem(policy_lab.BIN_VERSIONS, ("fallback", "pile"), "new pile")
    monkeypatch.setitem(policy_lab.BIN_SAME_AT, ("fallback", "pile"), {(1, 1): ("old pile",)})
    pile = {**two, "bin": "pile", "versions": {"fallback": "old pile"}, "visible": 1, "capacity": 1}
    assert policy_lab._fresh(pile)["gaps"] == {"fallback": 0.01}
    assert policy_lab._fresh({**pile, "visible": 2})["gaps"] == {}
    assert policy_lab._fresh({**pile, "versions": {"fallback": "old"}})["gaps"] == {}    # the uniform list: not here

def test_an_older_version_counts_on_one_strategy_plans_in_the_settings_named_for_them_alone(monkeypatch):
    """A change of the several-strategy decisions at one location: BIN_SAME_AT_ON_ONE_STRATEGY keeps the older
    gaps of one-strategy plans in the settings it names, not those of two-strategy plans, nor elsewhere."""
    monkeypatch.setitem(policy_lab.BIN_VERSIONS, ("fallback", "pile"), "new pile")
    monkeypatch.setitem(policy_lab.BIN_SAME_AT, ("fallback", "pile"), {})
    monkeypatch.setitem(policy_lab.BIN_SAME_AT_ON_ONE_STRATEGY, ("fallback", "pile"), {(1, 1): ("old pile",)})
    one = {"gaps": {"fallback": 0.01}, "versions": {"fallback": "old pile"}, "two_strategies": False, "bin": "pile",
           "visible": 1, "capacity": 1}
    assert policy_lab._fresh(one)["gaps"] == {"fallback": 0.01}
    assert policy_lab._fresh({**one, "two_strategies": True})["gaps"] == {}
    assert policy_lab._fresh({**one, "capacity": 2})["gaps"] == {}
    assert policy_lab._fresh({**one, "versions": {"fallback": "older"}})["gaps"] == {}


def test_the_current_pile_version_keeps_what_its_change_did_not_touch():
    """The start's cap for the first installations at one location changed every plan there (as the locations'
    factor at one location did before it): every pile gap of the three versions before stays current with two
    locations or more (or unlimited), none with one location; the version before those (the locations' factor
    at two or more) nowhere."""
    rec = {"gaps": {"fallback": 0.01}, "bin": "pile"}
    befores = (policy_lab._PILE_BEFORE_EARLY, policy_lab._PILE_BEFORE_ONE_LOCATION, policy_lab._PILE_BEFORE_ONE_LOOK)
    for before in befores:
        for visible in (1, 2, 3):
            for capacity in (1, 2, 3, None):
                for two in (False, True):
                    kept = policy_lab._fresh({**rec, "versions": {"fallback": before}, "visible": visible,
                                              "capacity": capacity, "two_strategies": two})
                    assert (kept["gaps"] != {}) == (capacity != 1), (before, visible, capacity, two)
    older = {**rec, "versions": {"fallback": policy_lab._PILE_BEFORE_LOCATIONS}, "visible": 1, "two_strategies": False}
    for capacity in (1, 2, None):
        assert policy_lab._fresh({**older, "capacity": capacity})["gaps"] == {}
    assert policy_lab.policy_version("fallback", "pile") not in befores


def test_a_policy_skipped_at_another_version_is_run_again(monkeypatch):
    """A policy skipped (out of time, or past a counted cut) at an earlier version is not a reason to leave its
    plan-setting alone: the skip is dropped as a stale gap is, and the policy is missing again; a skip at the
    current version stands, and a policy without versions keeps its skips."""
    monkeypatch.setitem(policy_lab.BIN_VERSIONS, ("fallback", "pile"), "new pile")
    rec = {"gaps": {"paper": 0.1}, "policy_skipped": {"fallback": "over 12,000 states", "lookahead": "over 600 s"},
           "versions": {"fallback": "old pile"}, "two_strategies": True, "bin": "pile", "visible": 1, "capacity": 1}
    done: dict = {}
    policy_lab._keep(done, "0:16-16:r2-16x2:1:1:pile:2000000", dict(rec), 2_000_000)
    (fresh,) = done.values()
    assert fresh["policy_skipped"] == {"lookahead": "over 600 s"}
    assert policy_lab._missing(fresh, ("fallback", "lookahead", "paper"), False) == ("fallback",)
    current = {**rec, "versions": {"fallback": "new pile"}}
    assert policy_lab._fresh(current)["policy_skipped"] == rec["policy_skipped"]
    assert policy_lab._missing(policy_lab._fresh(current), ("fallback",), False) == ()

# ------------------------------------------------------------------ the SALBP walls: the largest attempt per plan-setting

WALL = "0:salbp:KILBRID:1:2:uniform:"


def _single(lines, cap=2_000_000):
    """The SALBP table's cell for ``WALL`` read from synthetic lines, as the tables are written at ``cap``."""
    from types import SimpleNamespace

    done: dict = {}
    for key, rec in lines:
        policy_lab._keep(done, key, dict(rec), cap)
    job = policy_lab.Job(WALL + str(cap), "SALBP", SimpleNamespace(name="KILBRID"), (1, 2, "uniform"), False)
    (cell,) = policy_lab.cells([job], done).values()
    return cell


COUNTED = {"skipped": "optimum over 2,000,000 states: about 163,126,073 (estimated from the order's down-sets; "
                      "at least 2,000,588)", "estimate": 163126073}
TIMED = {"skipped": "optimum over 1500 s", "estimate": 38064092, "low": 13416529,
         "measured": {"states": 21_000_000, "cpu": 1200.5, "rss_mb": 1300, "bytes": 900 * 2 ** 20}}
ESTIMATED = {"skipped": "optimum over 60,000,000 states: about 163,126,073 (estimated from the order's down-sets; "
                        "at least 38,284,404)", "estimate": 163126073}


def test_a_skip_at_a_larger_cap_wins_over_one_at_a_smaller_in_any_order_of_the_lines():
    for lines in ([(WALL + "2000000", COUNTED), (WALL + "200000000", TIMED), (WALL + "60000000", ESTIMATED)],
                  [(WALL + "200000000", TIMED), (WALL + "60000000", ESTIMATED), (WALL + "2000000", COUNTED)]):
        cell = _single(lines)
        assert cell.rows == [] and cell.skipped == [("KILBRID", TIMED["skipped"])]
        assert cell.walls["KILBRID"]["cap"] == 200_000_000
        text = policy_lab.wall_text(cell.walls["KILBRID"])
        assert text == ("over 1,500 s at the 200,000,000-state cap (about 38,064,092 states estimated; 21,000,000 "
                        "states finished in 1,200.5 CPU s, the process's peak memory 1,300 MB (the programme's table 900 MB))")
    cell = _single([(WALL + "2000000", COUNTED), (WALL + "60000000", ESTIMATED)])
    assert policy_lab.wall_text(cell.walls["KILBRID"]) == (
        "about 163,126,073 states estimated before the work, over the 60,000,000-state cap (at least 38,284,404 "
        "counted); not run")


def test_an_optimum_found_at_any_cap_wins_over_every_skip():
    exact = {"optimum": 120.5, "states": 27_523_885, "gaps": {"lookahead": 0.0}}
    for order in ((0, 1, 2), (2, 1, 0)):
        lines = [(WALL + "2000000", COUNTED), (WALL + "40000000", exact), (WALL + "200000000", TIMED)]
        cell = _single([lines[i] for i in order])
        assert cell.skipped == [] and cell.walls == {}
        assert [(r["optimum"], r["states"]) for r in cell.rows] == [(120.5, 27_523_885)]
        table = policy_lab.single_table({("SALBP", (1, 2, "uniform")): cell}, ["lookahead"])
        assert table[-1] == "| KILBRID | uniform, 1 visible, buffer 2 | 120.5000 | 27,523,885 | +0.000% |"


def test_a_skip_counted_over_the_cap_is_certain_only_where_the_lower_bound_is_over_it():
    over = {**ESTIMATED, "skipped": ESTIMATED["skipped"].replace("38,284,404", "60,001,037"), "cap": 60_000_000}
    assert policy_lab.wall_text(over) == ("over 60,000,000 states: at least 60,001,037 counted before the work "
                                          "(about 163,126,073 states estimated)")
    big = {"skipped": "optimum over 2,000,000 states: about 1.1e+15 (estimated; at least 3.5e+13)",
           "estimate": 10 ** 15, "cap": 2_000_000}
    assert policy_lab.wall_text(big).startswith("over 2,000,000 states: at least 3.5e+13 counted before the work")


def test_an_optimum_cut_by_its_time_records_how_far_it_got():
    plan = policy_lab.random_plan(policy_lab.random.Random(1), 12, 1, 0.2)
    r = policy_lab.measure(plan, 1, 2, seconds=0.0)
    assert r["skipped"] == "optimum over 0 s" and r["low"] <= r["estimate"]
    measured = r["measured"]
    assert measured["states"] >= 0 and measured["cpu"] >= 0 and measured["bytes"] > 0 and measured["rss_mb"] > 0
    assert "states finished in" in policy_lab.describe((1, 2, "uniform"), r, plan.name)


def test_a_policy_cut_by_its_states_records_how_far_its_evaluation_got():
    plan = policy_lab.random_plan(policy_lab.random.Random(1), 12, 1, 0.2)
    r = policy_lab.measure(plan, 1, 2, only={"paper"}, policy_states=50)
    assert r["policy_skipped"] == {"paper": "over 50 states"}
    assert 50 <= r["policy_measured"]["paper"]["states"] < 100      # the cut, and the finished states it adds
    cell = policy_lab.Cell([{**r, "plan": plan.name}], [])
    row = policy_lab.single_table({("The folder", (1, 2, "uniform")): cell}, ["paper"])[-1]
    assert "evaluation over 50 states (" in row and "states finished in" in row


def test_the_count_before_the_work_is_of_the_plan_the_programme_stores():
    """The compiled optimum merges interchangeable parts: a plan whose merged programme fits the cap is run,
    though the plan as declared has more states."""
    from opportune import make_plan
    from opportune.engine import OrderEngine
    from opportune.policies.optimal import optimum_engine
    from opportune.policies.states import estimate_states

    screws = make_plan(["base", *[f"s{i}" for i in range(6)], "lid"],
                       {**{f"s{i}": ["base"] for i in range(6)}, "lid": [f"s{i}" for i in range(6)]})
    engine = OrderEngine(screws)
    merged = estimate_states(optimum_engine(engine), visible=1, capacity=2).states
    declared = estimate_states(engine, visible=1, capacity=2).states
    assert merged < declared
    r = policy_lab.measure(screws, 1, 2, max_states=merged, only=())
    assert "skipped" not in r and r["states"] == merged
    assert "skipped" in policy_lab.measure(screws, 1, 2, max_states=merged, only=(), python=True)


def test_a_gap_estimated_from_runs_is_recorded_as_such_and_near_the_exact_one():
    """``--estimate-runs``: past ``--estimate-above`` states the fallback's gap comes from seeded runs, with
    its standard error; it agrees with the exact evaluation, and the documents say which gaps are estimated."""
    plan = policy_lab.random_plan(policy_lab.random.Random(4), 9, 1, 0.2)
    exact = policy_lab.measure(plan, 2, 1, "pile", only={"paper"})
    est = policy_lab.measure(plan, 2, 1, "pile", only={"paper"}, estimate=(300, 0))
    assert "estimated" not in exact and exact["gaps"]["paper"] > 0
    e = est["estimated"]["paper"]
    assert est["gaps"]["paper"] == e["gap"] and e["runs"] == 300 and e["seed"] == policy_lab.ESTIMATE_SEED
    assert abs(e["gap"] - exact["gaps"]["paper"]) <= 4 * e["se"]
    assert "estimated" not in policy_lab.measure(plan, 2, 1, "pile", only={"paper"}, estimate=(300, est["states"]))
    cell = policy_lab.Cell([{**est, "plan": plan.name}], [])
    (line,) = policy_lab.estimated_text({("9", (2, 1, "pile")): cell}, ["paper"])
    assert line.startswith(f"- 9, pile, 2 visible, buffer 1, {plan.name}, paper: {policy_lab.pct(e['gap'])}, standard error")
    row = policy_lab.single_table({("The folder", (2, 1, "pile")): cell}, ["paper"])[-1]
    assert f"| {policy_lab.pct(e['gap'])} ± {100 * e['se']:.3f}% (300 runs) |" in row


def test_an_exact_gap_measured_later_drops_the_earlier_estimate():
    versions = {"fallback": policy_lab.policy_version("fallback", "pile")}
    est = {"gaps": {"fallback": 0.004, "paper": 0.02}, "optimum": 2.0, "states": 9, "bin": "pile", "versions": versions,
           "estimated": {"fallback": {"gap": 0.004, "se": 0.001}}}
    done = _read([(KEY + "2000000", est),
                  (KEY + "2000000", {"gaps": {"fallback": 0.003}, "optimum": 2.0, "states": 9, "bin": "pile", "versions": versions})])
    rec = done[KEY + "2000000"]
    assert rec["gaps"] == {"fallback": 0.003, "paper": 0.02} and rec["estimated"] == {}
    kept = _read([(KEY + "2000000", est), (KEY + "2000000", {"gaps": {"lookahead": 0.0}, "optimum": 2.0, "states": 9})])
    assert kept[KEY + "2000000"]["estimated"] == est["estimated"]
