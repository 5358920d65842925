"""``simulate``: the paper's comparison by simulation (every strategy, a bin model, Monte Carlo trials), a
recorded study run again (``--from``), and the certified lower bound beside it (``--bound``).

The study is :mod:`opportune.study.simulate`'s; what is here is option plumbing (the settings of a
``results.json`` with what the command line says instead), the table and the notes.  ``--products`` runs
another study (:mod:`opportune.cli.products`).

Imports: typer only; the study loads when the command runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from opportune.cli.common import (PLAN_ARG, complete_plan, err, fail, json_option, load_or_exit, out, policy_names,
                                  progress_bar)
from opportune.cli.products import simulate_products
from opportune.limits import MAX_BUFFER

if TYPE_CHECKING:
    from opportune.planning.plan import Plan


def _recorded_study(path: Path, as_json: bool) -> tuple[dict, Plan]:
    """The settings and the plan a ``results.json`` records, or exit with what is wrong with the file
    (read within the bounds of :mod:`opportune.formats.results`)."""
    from opportune.formats.loader import plan_from_dict
    from opportune.formats.results import ResultsError, read_recorded_study
    from opportune.planning.plan import PlanError

    try:
        prov = read_recorded_study(path)
    except ResultsError as exc:
        fail(str(exc), as_json=as_json)
    try:
        plan = plan_from_dict(prov["plan"], file=f"{path}: provenance.plan")
    except PlanError as exc:
        fail(f"{path}: the recorded plan is not valid: {exc}", as_json=as_json)
    from opportune.study.simulate import plan_sha256

    if prov.get("plan_sha256") not in (None, plan_sha256(plan)):
        fail(f"{path}: the recorded plan does not match its recorded hash (plan_sha256): the file was edited; "
             "rerun from the plan file instead", as_json=as_json)
    return prov["study"], plan


OPTIMAL_DEFAULT_UNITS = 14  # above this, the optimum is only attempted when asked for


def _check_report_path(path: Path, products: Optional[int], out_dir: Optional[Path], as_json: bool) -> None:
    """Exit with what to do when ``simulate --report PATH`` could not be written (before the study runs);
    a report inside ``--out DIR`` is fine, that directory is made before the report is written."""
    from opportune.study.report_html import REPORT_SUFFIXES

    if products is not None:
        fail("--report is the paper's comparison of strategies on one plan; it is not made for --products: "
             "leave out one of them", 2, as_json=as_json)
    if path.is_dir():
        fail(f"--report {path} is a directory: give a file name, such as {path / 'report.html'}", 2, as_json=as_json)
    if path.suffix.lower() not in REPORT_SUFFIXES:
        fail(f"--report {path}: the report is one HTML page; give a file name ending in .html", 2, as_json=as_json)
    if not path.parent.is_dir() and not (out_dir is not None and path.parent.resolve() == out_dir.resolve()):
        fail(f"--report {path}: the directory {path.parent} does not exist: create it, or give another path", 2,
             as_json=as_json)


def simulate(
    ctx: typer.Context,
    plan_file: Optional[Path] = typer.Argument(None, help=PLAN_ARG.help + " (not with --from)", show_default=False,
                                               autocompletion=complete_plan),
    from_results: Optional[Path] = typer.Option(
        None, "--from", show_default=False,
        help="Run the study recorded in a results.json again (its plan and settings; options given here override "
             "theirs): the same seed gives the same numbers"),
    strategies: Optional[str] = typer.Option(None, "--strategies", help="Comma-separated; default: all that apply"),
    trials: int = typer.Option(10_000, "--trials", min=1, help="Trials per strategy"),
    seed: int = typer.Option(0, "--seed", help="Seed: the same seed gives the same numbers on any number of workers"),
    bin_model: Optional[str] = typer.Option(
        None, "--bin", help="uniform, weighted, pile, conveyor or physics (MuJoCo: parts heaped in a bin, seen through "
                            "occlusion; pip install 'opportune[physics]') (default: plan, else uniform)"),
    visible: Optional[int] = typer.Option(None, "--visible", min=1, help="Parts seen per look (default: plan, else 2)"),
    buffer_capacity: Optional[int] = typer.Option(None, "--buffer-capacity", min=0, max=MAX_BUFFER, help="Buffer locations (default: unlimited)"),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, help="Local worker processes (default: all cores)"),
    dask: Optional[str] = typer.Option(None, "--dask", help="Address of a Dask distributed scheduler"),
    out_dir: Optional[Path] = typer.Option(None, "--out", help="Write results.json, trials.csv and plots here"),
    report_file: Optional[Path] = typer.Option(
        None, "--report", show_default=False,
        help="Also write the comparison on one self-contained HTML page (setup, table, figures, notes) to this "
             "file, e.g. report.html"),
    as_json: bool = json_option("Print the results as JSON (errors too)"),
    training_runs: int = typer.Option(200, "--training-runs", min=1, help="Training runs of the quantify strategy"),
    optimal_states: int = typer.Option(500_000, "--optimal-states", min=1, help="State limit of the optimum"),
    count_time_limit: Optional[float] = typer.Option(
        None, "--count-time-limit", min=0.1, show_default=False,
        help="Seconds the opportunistic policy's first exact counts may take (default: 10 when it is asked for "
             "with --strategies, else 2: a plan that slow to count takes minutes per trial)"),
    motion_cost: Optional[float] = typer.Option(None, "--motion-cost", min=0, show_default=False,
                                                help="Time of one robot motion (default: the plan's, else 1)"),
    shake_cost: Optional[float] = typer.Option(None, "--shake-cost", min=0, show_default=False,
                                               help="Time of one shake (default: the plan's, else 1)"),
    look_cost: Optional[float] = typer.Option(None, "--look-cost", min=0, show_default=False,
                                              help="Time of one look (default: the plan's, else 0)"),
    decision_budget: Optional[float] = typer.Option(
        None, "--decision-budget", min=1e-6, show_default=False,
        help="Seconds per opportunistic decision: exact when the counts fit, else estimated (the numbers then "
             "depend on the machine's speed; default: every decision exact, the same numbers everywhere)"),
    products: Optional[int] = typer.Option(
        None, "--products", show_default=False,
        help="Build this many copies of the plan (1-16) on as many fixtures from one bin, and compare with "
             "as many separate cells and with one product after another (policies: --strategies, default "
             "paper,lookahead)"),
    bound: bool = typer.Option(
        False, "--bound", help="Also a certified lower bound on the expected time of every online policy, with its "
                               "95% interval, beside each policy's mean (information relaxation; uniform and "
                               "weighted bins; on min(--trials, 200) bins)"),
    penalty: Optional[str] = typer.Option(
        None, "--penalty", show_default=False,
        help="The bound's penalty (with --bound): auto (the default: the optimum's values where they fit, else "
             "relaxed with a limited buffer and motions with an unlimited one), motions (the motions still "
             "needed), relaxed (the exact optimum of a relaxed plan: the most-ordered parts kept), none (the "
             "clairvoyant bound) or optimal (the optimum's values: the bound is the optimum)"),
):
    """Run the paper's comparison by simulation: every strategy, a bin model, Monte Carlo trials."""
    if report_file is not None:   # checked before any work: a study of minutes must not end in "cannot write"
        _check_report_path(report_file, products, out_dir, as_json)
    _check_penalty(bound, penalty, as_json)
    settings = dict(trials=trials, seed=seed, bin_model=bin_model, visible=visible, buffer_capacity=buffer_capacity,
                    motion_cost=motion_cost, shake_cost=shake_cost, look_cost=look_cost,
                    decision_budget=decision_budget)
    if products is not None:   # several products at once: its own study
        return simulate_products(ctx, plan_file, products, strategies=strategies, as_json=as_json, **settings)
    if (plan_file is None) == (from_results is None):
        fail("give a plan file, or --from results.json to run a recorded study again (not both)", 2, as_json=as_json)
    from opportune.study.report import summary
    from opportune.study.simulate import StudyError

    settings.update(training_runs=training_runs, optimal_states=optimal_states, count_time_limit=count_time_limit)
    plan, recorded, given = _study_plan(ctx, plan_file, from_results, as_json)
    explicit, names = _strategy_names(plan, strategies, bin_model or plan.simulation.get("bin", "uniform"))
    explicit = explicit or recorded is not None   # the recorded strategies, all of them: none is quietly left out
    try:
        config = _study_config(plan, recorded, given, names, explicit, settings)
        _check_study_bound(config, bound, penalty, as_json)
        config, prepared, decision_budget = _prepare(config, explicit, decision_budget, from_results is None)
        result = _run(config, prepared, workers, dask, total=trials * len(config.strategies))
    except (StudyError, ValueError) as exc:
        fail(str(exc))
    doc = summary(result)
    if bound:
        doc["bound"] = _study_bound(config, doc, penalty or "auto", as_json)
    written = _write_study(result, doc, out_dir, report_file)
    if as_json:
        print(json.dumps(doc, indent=2))
    else:
        _print_study(config, result, doc, decision_budget, written, report_file)
    if result.interrupted:
        err().print("interrupted: the table shows the trials that finished")
        raise typer.Exit(130)


def _study_plan(ctx: typer.Context, plan_file: Optional[Path], from_results: Optional[Path],
                as_json: bool) -> tuple[Plan, Optional[dict], set[str]]:
    """The study's plan, the settings a ``results.json`` records (None for a plan file) and the options the
    command line gives (those override the recorded settings)."""
    if from_results is None:
        return load_or_exit(plan_file, json_errors=as_json, ways=True), None, set()
    recorded, plan = _recorded_study(from_results, as_json)
    # by name: typer carries its own copy of click, whose enum is not the click package's
    given = {name for name in ctx.params if getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"}
    return plan, recorded, given


def _strategy_names(plan: Plan, strategies: Optional[str], chosen_bin: str) -> tuple[bool, list[str]]:
    """Whether ``--strategies`` names the strategies, and their names now: the given ones, else every one that
    applies (the optimum only on plans of at most :data:`OPTIMAL_DEFAULT_UNITS` units, with a note)."""
    from opportune.study.simulate import OPTIMAL_BINS, STRATEGIES

    explicit = strategies is not None
    names = [s.strip() for s in (strategies or "").split(",") if s.strip()] if explicit else \
        [s for s in STRATEGIES if s != "optimal" or (chosen_bin in OPTIMAL_BINS and plan.n_units <= OPTIMAL_DEFAULT_UNITS)]
    if not explicit and chosen_bin in OPTIMAL_BINS and plan.n_units > OPTIMAL_DEFAULT_UNITS:
        err().print(f"note: 'optimal' left out: its state space grows exponentially and {plan.n_units} parts is "
                    f"beyond the default ({OPTIMAL_DEFAULT_UNITS}); ask for it with --strategies to try anyway")
    if explicit and not names:
        fail("--strategies is empty: name at least one of " + ", ".join(STRATEGIES), 2)
    return explicit, policy_names(names)


#: ``simulate``'s options that are settings of the study, by the study's name for them.
SETTINGS = {"trials": "trials", "seed": "seed", "bin": "bin_model", "visible": "visible",
            "buffer_capacity": "buffer_capacity", "training_runs": "training_runs", "optimal_states": "optimal_states",
            "count_time_limit": "count_time_limit", "decision_budget": "decision_budget"}


def _study_config(plan: Plan, recorded: Optional[dict], given: set[str], names: list[str], explicit: bool,
                  settings: dict):
    """The study's settings: those a ``results.json`` records with what the command line says instead where it
    says something, or the command line's with the plan's where it says nothing."""
    from dataclasses import replace

    from opportune.study.simulate import StudyConfig
    from opportune.worlds import CellModel, TimeModel

    strategies = tuple(dict.fromkeys(names))
    if recorded is not None:
        config = StudyConfig.from_settings(plan, recorded)
        overrides = {key: settings[option] for key, option in SETTINGS.items() if option in given}
        if "strategies" in given:
            overrides["strategies"] = strategies
        cost = {k: settings[f"{k}_cost"] for k in ("motion", "shake", "look") if f"{k}_cost" in given}
        if cost:
            overrides["costs"] = replace(config.costs, **cost)
        return replace(config, **overrides).validate()
    s, sim = settings, plan.simulation
    costs = TimeModel.from_plan(plan, motion=s["motion_cost"], shake=s["shake_cost"], look=s["look_cost"])
    return StudyConfig(
        cell=CellModel.from_plan(plan),
        plan=plan, strategies=strategies, trials=s["trials"], seed=s["seed"],
        bin=s["bin_model"] or sim.get("bin", "uniform"), visible=s["visible"] or sim.get("visible", 2),
        buffer_capacity=s["buffer_capacity"] if s["buffer_capacity"] is not None else sim.get("buffer_capacity"),
        costs=costs, training_runs=s["training_runs"], optimal_states=s["optimal_states"],
        count_time_limit=s["count_time_limit"] if s["count_time_limit"] is not None else (10.0 if explicit else 2.0),
        decision_budget=s["decision_budget"],
    ).validate()


def _prepare(config, explicit: bool, decision_budget: Optional[float], may_budget: bool):
    """The study prepared (each strategy's first decisions and training), with the settings it runs with and the
    decision budget the notes quote: a counting policy whose first exact counts take too long decides within the
    sequencer's budget instead (unless a budget was given, or the study is a recorded one); any other strategy
    that cannot run is left out with a note, unless it was asked for."""
    from dataclasses import replace

    from opportune.study.simulate import COUNTING_STRATEGIES, StrategyUnavailable, prepare

    while True:
        try:
            return config, prepare(config), decision_budget
        except StrategyUnavailable as exc:
            if (exc.strategy in COUNTING_STRATEGIES and config.decision_budget is None
                    and decision_budget is None and may_budget):
                # A plan too large to count every look exactly in reasonable time (ARC111): the counting
                # policies decide within the sequencer's budget instead of being left out, and say so.
                from opportune.sequencer import DEFAULT_BUDGET

                config = replace(config, decision_budget=DEFAULT_BUDGET)
                decision_budget = DEFAULT_BUDGET
                err().print(f"note: the exact counts of {config.plan.name}'s first look take longer than "
                            f"{config.count_time_limit:g} s: the counting policies decide within "
                            f"{1000 * DEFAULT_BUDGET:g} ms per decision, exact where the counts fit and "
                            "estimated elsewhere (set --decision-budget to choose)")
                continue
            if explicit or len(config.strategies) == 1:
                raise
            err().print(f"note: {exc} — leaving '{exc.strategy}' out")
            config = replace(config, strategies=tuple(s for s in config.strategies if s != exc.strategy))


def _run(config, prepared, workers: Optional[int], dask: Optional[str], total: int):
    """The study's trials, with a progress bar on a terminal (standard error)."""
    from opportune.study.simulate import run_study

    progress = progress_bar()
    with progress:
        task = progress.add_task("simulating", total=total)
        return run_study(config, workers=workers, dask_address=dask, prepared=prepared,
                         progress=lambda s, n: progress.advance(task, n))


def _write_study(result, doc: dict, out_dir: Optional[Path], report_file: Optional[Path]) -> Optional[list]:
    """Write ``--out``'s files and ``--report``'s page; the files written to ``--out`` (None without it)."""
    from opportune.study.report import write_outputs

    written = None
    if out_dir:
        try:
            written = write_outputs(result, out_dir)
        except OSError as exc:
            fail(f"cannot write to {out_dir}: {exc.strerror or exc}")
    if report_file:
        from opportune.study.report_html import write_report

        try:
            write_report(result, report_file, doc)
        except OSError as exc:
            fail(f"cannot write the report to {report_file}: {exc.strerror or exc}")
    return written


def _print_study(config, result, doc: dict, decision_budget: Optional[float], written: Optional[list],
                 report_file: Optional[Path]) -> None:
    """The study's table, the optimum, the paired differences, the bound and the notes."""
    from rich.table import Table

    from opportune.study.report import TABLE_HEADER, table_rows
    from opportune.study.simulate import COUNTING_STRATEGIES

    cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
    table = Table(title=f"{config.plan.name}: {config.bin} bin, {config.visible} visible, buffer {cap}, "
                        f"{doc['trials']:,} trials, seed {config.seed}")
    for i, col in enumerate(TABLE_HEADER):
        table.add_column(col, justify="left" if i == 0 else "right")
    for row in table_rows(doc):
        table.add_row(*row)
    out().print(table)
    if result.prepared.optimal_start is not None:
        out().print(f"optimal expected time (exact): {result.prepared.optimal_start:.4f} "
                    f"({result.prepared.optimal_states:,} states, {result.prepared.optimal_seconds:.1f} s)")
    paired = [(name, s["paired"]) for name, s in doc["strategies"].items() if "paired" in s]
    if paired:
        out().print(f"paired with {paired[0][1]['with']} on the same bins (mean difference of time, 95% interval): "
                    + "; ".join(f"{name} {p['mean_difference']:+.3f} ({p['ci95'][0]:+.3f} .. {p['ci95'][1]:+.3f})"
                                for name, p in paired))
    if "bound" in doc:   # simulate --bound
        out().print(_bound_line(doc["bound"]))
    for note in doc["notes"]:
        out().print(f"note: {note}")
    budgeted = [s for s in config.strategies if s in COUNTING_STRATEGIES]
    if decision_budget is not None and budgeted:
        out().print(f"note: {', '.join(budgeted)} decided within {1000 * decision_budget:g} ms per decision "
                    "(estimated where exact counts did not fit): "
                    f"{'its' if len(budgeted) == 1 else 'their'} numbers depend on this machine's speed")
    if written is not None:
        out().print(f"wrote {', '.join(str(p) for p in written)}")
    if report_file:
        out().print(f"wrote the report: {report_file}")


BOUND_BINS = ("uniform", "weighted")
BOUND_TRIALS = 200   # bins of simulate's lower bound, at most


def _check_penalty(bound: bool, penalty: Optional[str], as_json: bool) -> None:
    """Exit with what to do when ``--penalty`` is not one of the bound's, or is given without ``--bound``."""
    from opportune.study.bounds import PENALTIES

    if penalty is None:
        return
    if penalty not in PENALTIES:
        fail(f"--penalty {penalty!r} is not a penalty of the bound: choose from {', '.join(PENALTIES)}", 2,
             as_json=as_json)
    if not bound:
        fail("--penalty chooses the penalty of the lower bound: give --bound too", 2, as_json=as_json)


def _bound_settings(config, penalty: str) -> dict:
    """The bound's request for ``simulate``'s world: the same plan, bin, costs, trials (at most 200) and seed."""
    return dict(visible=config.visible, capacity=config.buffer_capacity, bin=config.bin, penalty=penalty,
                trials=max(2, min(config.trials, BOUND_TRIALS)),
                weights=config.weights if config.bin == "weighted" else None)


def _check_study_bound(config, bound: bool, penalty: Optional[str], as_json: bool) -> None:
    """With ``--bound``, refuse a bound that cannot be computed as asked before the study runs: a bin it is not
    defined for, or a request it refuses (the optimum's penalty on a plan too large for it is counted, within
    2 s, not solved)."""
    from opportune.study.bounds import BoundError, check_request

    if not bound:
        return
    if config.bin not in BOUND_BINS:   # before the study: refused at once, not after it
        fail(f"--bound is defined for the {' and '.join(BOUND_BINS)} bins, not '{config.bin}': "
             "leave --bound out or change --bin", 2, as_json=as_json)
    try:
        check_request(config.plan, **_bound_settings(config, penalty or "auto"))
    except BoundError as exc:
        fail(f"--bound: {exc}", 2, as_json=as_json)


def _study_bound(config, doc: dict, penalty: str, as_json: bool) -> dict:
    """``simulate --bound``: the certified lower bound on the study's world, and each policy's mean against it."""
    from opportune.study.bounds import BoundError, lower_bound, policy_gaps

    try:
        r = lower_bound(config.plan, seed=config.seed, costs=config.costs, **_bound_settings(config, penalty))
    except BoundError as exc:
        fail(f"--bound: {exc}", 2, as_json=as_json)
    found = r.to_dict()
    found["policies"] = policy_gaps(r, {name: s["time"] for name, s in doc["strategies"].items()})
    return found


def _bound_line(b: dict) -> str:
    """The bound, each policy's mean against it (a signed gap in words), and what a mean below it means."""
    from opportune.study.bounds import describe_gaps

    return (f"lower bound on any online policy's expected time (certified: {b['method']}): "
            f"{b['mean']:.3f} ± {b['half_width']:.3f} (95%); each policy's mean against it: "
            + describe_gaps(b["policies"]))
