"""The ``opportune`` command line.

Every command loads the plan once through :mod:`opportune.formats` and asks
the engine; user mistakes (a bad file, an unknown part, an inadmissible
prefix) print a message that says where and what to do, and exit non-zero,
never with a traceback.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from typer.core import TyperGroup

from opportune import cli_count
from opportune.limits import MAX_BUFFER

if TYPE_CHECKING:
    from rich.console import Console

    from opportune.formats import CheckResult
    from opportune.planning.plan import Plan

# Start-up (issue 11): this module imports only typer.  rich, the plan loader, the engine and every
# command's own machinery load when a command needs them, so `opportune count --help` never pays for
# them (tests/test_cli.py checks that the heavy packages stay out; benchmarks/bench_startup.py times it).


class _Group(TyperGroup):
    """The main group, with a help flag that is ``False`` rather than ``None`` when not given.

    typer (0.29) coerces every parameter's value through a pydantic adapter that it builds on first
    use, except a bool flag whose value is already a bool.  An absent help flag is ``None``, so every
    run, ``opportune count --help`` included, imported pydantic (~0.1 s) for the main group's
    ``--help`` alone.  ``False`` means the same to the flag's callback.
    """

    def get_help_option(self, ctx):
        option = super().get_help_option(ctx)
        if option is not None and option.default is None:
            option.default = False
        return option


app = typer.Typer(
    cls=_Group,
    name="opportune",
    help="Least-commitment planning, scheduling and opportunistic execution (Fox & Kempf).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # Help and usage errors in click's plain format: typer's rich help imports rich.markdown,
    # rich.traceback, pygments and attrs (~0.1 s, most of `opportune count --help`).  Help uses the
    # terminal's width, up to 120 columns, as the rich panels did.
    rich_markup_mode=None,
    context_settings={"max_content_width": 120, "help_option_names": ["-h", "--help"]},
)
_consoles: dict[str, Console] = {}


def _console(stderr: bool) -> Console:
    """The shared stdout (``out``) or stderr (``err``) console, made on first use."""
    key = "err" if stderr else "out"
    if key not in _consoles:
        import os

        from rich.console import Console

        class Printable(Console):
            """Every text printed is made printable first: control characters (an ESC sequence in a file
            name, a look or a message quoting bad input) are written as escapes, never sent raw.  Rich
            adds its own styles after this, so colours are kept."""

            def render_str(self, text, **kwargs):
                return super().render_str(printable(text), **kwargs)

        console = Printable(stderr=stderr, highlight=False, soft_wrap=True)
        if not stderr and not console.is_terminal and "COLUMNS" not in os.environ:
            console.width = 132  # piped or logged output has no width of its own: rich would squeeze tables into 80
        _consoles[key] = console
    return _consoles[key]


printable = cli_count.printable   # one escaping of control characters for every command's output


def _out() -> Console:
    return _console(stderr=False)


def _err() -> Console:
    return _console(stderr=True)


def __getattr__(name: str):  # ``cli.out`` and ``cli.err``, as before, without making them at import
    if name in ("out", "err"):
        return _console(stderr=name == "err")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _complete_plan(incomplete: str) -> list[str]:
    """Shell completion of a plan argument: the shipped plans by name (``salbp:``, ``example:``); nothing
    otherwise, so that the shell completes file names (the scripts fall back to them)."""
    from opportune.datasets import EXAMPLE_PREFIX, PREFIX, examples, salbp_names

    if ":" in incomplete or PREFIX.startswith(incomplete) or EXAMPLE_PREFIX.startswith(incomplete):
        names = [PREFIX + n for n in salbp_names()] + [EXAMPLE_PREFIX + n for n, _, _ in examples()]
        return [n for n in names if n.startswith(incomplete)] if incomplete else []
    return []


PLAN_ARG = typer.Argument(..., help="Plan file: .yaml, .json, SALBP .IN2 or .alb; - for standard input; salbp:NAME, example:NAME "
                                     "(shipped: see `opportune examples`)", show_default=False,
                          autocompletion=_complete_plan)


def _version(value: bool) -> None:
    if value:
        from opportune import __version__

        print(f"opportune {__version__}")
        raise typer.Exit()


@app.callback()
def _options(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                          help="Print the version and exit")) -> None:
    """Least-commitment planning, scheduling and opportunistic execution (Fox & Kempf)."""
    global _json_errors
    _json_errors = False   # a new command (the tests run many in one process); its --json sets it again


# Set by a command's --json (eagerly, before its other parameters): every error it reports is JSON too.
_json_errors = False


def _json_mode(value: bool) -> bool:
    global _json_errors
    _json_errors = _json_errors or bool(value)
    return value


def json_option(help: str = "Machine-readable output (errors too: {\"error\": {...}} on standard output)"):
    """The ``--json`` option of a command: its output and its errors as JSON."""
    return typer.Option(False, "--json", help=help, callback=_json_mode, is_eager=True)


def _print_error(error: dict, code: int) -> None:
    print(json.dumps({"error": {**error, "exit_code": code}}, indent=2))


def fail(message: str, code: int = 1, *, as_json: bool | None = None) -> None:
    """Print ``error: message`` (the one prefix; the message is text, never markup) and exit; under
    ``--json``, ``{"error": {"message": ...}}`` on standard output instead, for a caller reading JSON."""
    if _json_errors if as_json is None else as_json:
        _print_error({"message": message}, code)
    else:
        _err().print(f"[bold red]error:[/] {_escape(message)}", markup=True)
    raise typer.Exit(code)


def fail_problem(problem) -> None:
    """Print one :class:`~opportune.formats.problems.Problem` as ``check`` does (``where: error: ...``) and exit 1."""
    from opportune.formats.loader import CheckResult

    if _json_errors:
        _print_error({"message": problem.message, **problem.to_dict()}, 1)
    else:
        _print_problems(CheckResult(None, [problem]), _err())
    raise typer.Exit(1)


def _print_problems(result: CheckResult, console: Console) -> None:
    for p in result.problems:
        colour = "red" if p.severity == "error" else "yellow"
        where = f"{p.where}: " if p.where else ""
        hint = f" [dim]— {_escape(p.hint)}[/]" if p.hint else ""
        console.print(f"{_escape(where)}[{colour}]{p.severity}[/]: {_escape(p.message)}{hint}")


def _escape(text: str) -> str:
    """Text for rich: markup escaped, and characters that cannot be written as UTF-8 (the lone
    surrogates that stand for undecodable bytes in file names and arguments) written as escapes."""
    from rich.markup import escape

    return escape(text.encode("utf-8", "backslashreplace").decode("utf-8"))


def _current_names(names) -> list[str]:
    """Policy names with each former one (``opportunistic``) replaced by its name now, each name once; the
    former names get one note on standard error (the command line's deprecation notice)."""
    from opportune.policies.named import current_names, deprecation_note

    now, former = current_names(list(names), warn=False)
    if former:
        _err().print("note: " + _escape("; ".join(deprecation_note(n) for n in former)))
    return list(now)


def load_or_exit(path: Path, *, json_errors: bool = False) -> Plan:
    """Load a plan, or print every error and exit 1."""
    from opportune.formats.loader import CheckResult, read_plan

    result = read_plan(path)
    if not result.ok:
        if json_errors or _json_errors:
            _print_error({"message": f"{path}: not a valid plan ({len(result.errors)} error(s))", "file": str(path),
                          "problems": [p.to_dict() for p in result.problems]}, 1)
        else:
            _print_problems(CheckResult(None, result.errors), _err())
            # `check` says more only when there are warnings too (it lists the same errors, and nothing
            # more for a file it cannot read): the pointer to it is given only then
            warnings = len(result.problems) - len(result.errors)
            if warnings:
                _err().print(_escape(f"{path}: {len(result.errors)} error(s); `opportune check {path}` lists its "
                                     f"{warnings} warning(s) too"))
            elif len(result.errors) > 1:
                _err().print(_escape(f"{path}: {len(result.errors)} errors"))
        raise typer.Exit(1)
    return result.plan


# ---------------------------------------------------------------- check


@app.command()
def check(plan_files: list[Path] = typer.Argument(..., help="Plan files (any format `count` reads; - for standard "
                                                              "input; salbp:NAME, example:NAME)", show_default=False,
                                                  autocompletion=_complete_plan),
          as_json: bool = json_option("Machine-readable output: one file's document, or "
                                      "{\"valid\", \"files\": [...]} for several")):
    """Validate plans: exit 0 with a summary of each, or 1 with every problem of every file."""
    from opportune.formats.loader import read_plan
    from opportune.formats.summary import summarize

    docs, ok = [], True
    for i, plan_file in enumerate(plan_files):
        result = read_plan(plan_file)
        ok &= result.ok
        if as_json:
            doc = {"file": str(plan_file), "valid": result.ok, "problems": [p.to_dict() for p in result.problems]}
            if result.ok:
                doc.update(summarize(result.plan))
            docs.append(doc)
            continue
        if i:
            _out().print()
        _print_check(plan_file, result)
    if as_json:
        print(json.dumps(docs[0] if len(docs) == 1 else {"valid": ok, "files": docs}, indent=2))
    elif len(plan_files) > 1:
        _out().print(f"\n{len(plan_files)} files: " + ("all valid" if ok else "some invalid (above)"))
    raise typer.Exit(0 if ok else 1)


def _print_check(plan_file: Path, result) -> None:
    """``check``'s report of one file: its problems, or its summary (and warnings)."""
    from opportune.formats.summary import summarize

    if not result.ok:
        _print_problems(result, _out())
        n = len(result.errors)
        _out().print(f"[red]{_escape(str(plan_file))}: invalid[/] — {n} error{'s' if n != 1 else ''}"
                     + (f", {len(result.warnings)} warning(s)" if result.warnings else ""))
        return
    s = summarize(result.plan)
    _out().print(f"[bold]{_escape(s['plan'])}[/] ({_escape(str(plan_file))}): [green]valid[/]")
    units = f" ({s['units']} units)" if s["units"] != s["parts"] else ""
    _out().print(f"  parts: {s['parts']}{units}; strategies: {len(s['strategies'])}")
    for st in s["strategies"]:
        _out().print(f"  strategy '{_escape(st['name'])}': {st['declared']} constraints declared, "
                     f"{len(st['minimal'])} minimal, {st['implied']} implied in all (transitive closure)")
        shown = st["minimal"][:40]
        text = ", ".join(f"{a} -> {b}" for a, b in shown) or "(none: any order)"
        if len(st["minimal"]) > len(shown):
            text += f", … ({len(st['minimal']) - len(shown)} more; --json lists all)"
        _out().print(f"    minimal constraints: {_escape(text)}", crop=False)
    if result.warnings:
        _out().print(f"  {len(result.warnings)} warning(s):")
        _print_problems(result, _out())


# ---------------------------------------------------------------- count


def _count_option(name: str, **extra):
    """A ``count`` option from :data:`opportune.cli_count.OPTIONS` (the quick path reads the same table)."""
    flag, kind, default, text = cli_count.OPTIONS[name]
    if kind is None:
        return json_option(text)
    return typer.Option(default, flag, help=text, **extra)


@app.command(help=f"{cli_count.SUMMARY}\n\n{cli_count.DESCRIPTION}")
def count(
    plan_file: Path = typer.Argument(..., help=cli_count.PLAN_HELP, show_default=False, autocompletion=_complete_plan),
    after: Optional[str] = _count_option("after"),
    as_json: bool = _count_option("as_json"),
    time_limit: float = _count_option("time_limit", min=cli_count.MIN_TIME_LIMIT),
    max_memo: int = _count_option("max_memo"),
    threads: int = _count_option("threads", min=0, max=cli_count.MAX_THREADS),
):
    # the work is in opportune.cli_count, which opportune.launch runs without typer for a well-formed command line
    def write(line: str) -> None:
        if as_json:
            print(line)
        else:
            _out().print(line, markup=False, emoji=False)

    cli_count.run(plan_file, after, as_json, time_limit, max_memo, threads,
                  load=lambda path: load_or_exit(path, json_errors=as_json), fail=fail, write=write)


# ---------------------------------------------------------------- graph


@app.command()
def graph(
    plan_file: Path = PLAN_ARG,
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Output file: .svg, .png, .pdf or .dot"),
    fmt: Optional[str] = typer.Option(None, "--format", help="svg, png, pdf or dot (default: from the -o suffix)"),
    names: bool = typer.Option(False, "--names", help="Write each part's name under its id"),
    dpi: int = typer.Option(300, "--dpi", min=36, max=1200, help="Resolution of PNG output"),
    orders: bool = typer.Option(False, "--orders", help="For an AND/OR plan (`assemblies`), draw the partial "
                                "orders of its strategies instead of its AND/OR graph"),
    as_json: bool = json_option("Machine-readable output: without -o, each strategy's layered layout (parts with "
                                "their layer and x, y; edges with their points), as the service's dashboard draws it; "
                                "with -o, what was written (errors too: {\"error\": {...}})"),
):
    """Draw each strategy as a layered precedence diagram (like the paper's Figure 2); an AND/OR plan
    as its AND/OR graph (assemblies, their alternative ways and what each way joins)."""
    from opportune.formats.draw import DotMissing, render, to_dot

    plan = load_or_exit(plan_file, json_errors=as_json)
    andor = plan.andor is not None and not orders
    if as_json and output is None and fmt is None:
        from opportune.formats.summary import summarize
        from opportune.service.graph import layouts

        print(json.dumps({"plan": plan.name, "strategies": layouts(plan, summarize(plan))}, indent=2))
        return
    fmt = (fmt or (output.suffix.lstrip(".") if output else "dot")).lower()
    if fmt not in {"svg", "png", "pdf", "dot"}:
        fail(f"unknown format '{fmt}': use svg, png, pdf or dot", 2)
    if fmt == "dot" and output is None:
        if as_json:
            print(json.dumps({"plan": plan.name, "format": "dot", "dot": to_dot(plan, names=names, andor=andor)},
                             indent=2))
        else:
            sys.stdout.write(to_dot(plan, names=names, andor=andor))
        return
    if output is None:
        fail(f"give an output file with -o FILE.{fmt}", 2)
    try:
        if fmt == "dot":
            output.write_text(to_dot(plan, names=names, andor=andor))
        else:
            render(plan, output, fmt, names=names, dpi=dpi if fmt == "png" else None, andor=andor)
    except DotMissing as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"cannot write {output}: {exc.strerror or exc}")
    if as_json:
        print(json.dumps({"plan": plan.name, "format": fmt, "wrote": str(output)}, indent=2))
    else:
        _out().print(f"wrote {_escape(str(output))}")


# ---------------------------------------------------------------- replay


@app.command()
def replay(
    plan_file: Path = PLAN_ARG,
    looks_file: Path = typer.Argument(..., help="Looks file: one look per line ('-' for none), or JSON list of lists"),
    as_json: bool = json_option(),
    explain: bool = typer.Option(False, "--explain", help="Print the reasons of every decision"),
    buffer_capacity: Optional[int] = typer.Option(None, "--buffer-capacity", min=0, max=MAX_BUFFER,
                                                  help="Buffer locations (default: unlimited)"),
    decision_budget: Optional[float] = typer.Option(
        None, "--decision-budget", min=1e-6, show_default=False,
        help="Seconds per decision, as a cell would give: exact when the counts fit, else estimated and marked so "
             "(default: every decision exact)"),
    policy: str = typer.Option("paper", "--policy",
                               help="paper (the paper's rule), bin-first, slack, lookahead or rollout"),
):
    """Run a policy (the paper's rule by default) over a file of looks and print the trace
    like the paper's Table 1."""
    from rich.table import Table

    from opportune.formats.looks import LooksError, read_looks
    from opportune.sequencer import Sequencer, SequencerError

    plan = load_or_exit(plan_file, json_errors=as_json)
    try:
        looks = read_looks(looks_file)
    except LooksError as exc:
        fail_problem(exc.problem)
    from opportune.policies.named import UnknownPolicy, make_policy

    policy = _current_names([policy])[0]
    try:
        chosen = make_policy(policy, budget=decision_budget, visible=plan.simulation.get("visible", 2),
                             capacity=buffer_capacity)
    except UnknownPolicy as exc:
        fail(str(exc), 2)
    seq = Sequencer(plan, chosen, buffer_capacity=buffer_capacity, budget=decision_budget)
    stopped = None      # the look the policy's state contradicts: the trace up to it is printed, then why
    for i, look in enumerate(looks, start=1):
        try:
            seq.step(look)
        except SequencerError as exc:
            stopped = f"{looks_file}: look {i} ({' '.join(look) or '-'}): {exc}"
            if chosen.name != "paper":
                stopped += ("; looks recorded under another policy fit only that policy's actions: replay them "
                            "with it (the paper's Table 1: --policy paper)")
            break
    if stopped is None and seq.state.is_complete and not seq.finished:
        seq.step(())
    from opportune.policies.printable import printable_decision

    rows = seq.trace
    if as_json:
        doc = [row.to_dict() | ({"reasons": printable_decision(row.decision).to_dict()} if explain else {})
               for row in rows]
        for d in doc:
            d.pop("outcome", None)
        if stopped is not None:
            _print_error({"message": stopped, "trace": doc}, 1)
            raise typer.Exit(1)
        print(json.dumps(doc, indent=2))
        return
    title = "the paper's rule" if chosen.name == "paper" else f"{chosen.name} schedule"
    table = Table(title=f"{plan.name}: {title}" + (f" (stopped after {len(rows)} looks)"
                                                                 if stopped else ""))
    if explain:
        table.add_column("#", justify="right")
    for col in ("Visible", "Buffered", "Installed", "Action"):
        table.add_column(col, overflow="fold")
    for i, row in enumerate(rows, start=1):
        action = "" if row.action.kind == "done" else str(row.action)
        cells = [",".join(row.visible), ",".join(row.buffered), ",".join(row.installed), action]
        table.add_row(*([str(i)] if explain else []), *cells)
    _out().print(table)
    if explain:
        for i, row in enumerate(rows, start=1):
            _out().print(f"{i:>2}. " + _escape(printable_decision(row.decision).explain()).replace("\n", "\n   "),
                         crop=False)
    if stopped is not None:
        fail(stopped)
    if seq.state.is_complete:
        _out().print(f"complete: {','.join(seq.state.installed)}")
    else:
        left = ", ".join(f"{p}×{n}" if n > 1 else p for p, n in seq.state.schedule.remaining.items())
        _out().print(f"not complete after {len(looks)} looks; still to install: {left}")


# ---------------------------------------------------------------- simulate

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


@app.command()
def simulate(
    ctx: typer.Context,
    plan_file: Optional[Path] = typer.Argument(None, help=PLAN_ARG.help + " (not with --from)", show_default=False,
                                               autocompletion=_complete_plan),
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
    if products is not None:   # several products at once (issue 15): its own study, below
        return _simulate_products(ctx, plan_file, products, strategies=strategies, trials=trials, seed=seed,
                                  bin_model=bin_model, visible=visible, buffer_capacity=buffer_capacity,
                                  as_json=as_json, motion_cost=motion_cost, shake_cost=shake_cost,
                                  look_cost=look_cost, decision_budget=decision_budget)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
    from rich.table import Table

    from opportune.study.report import TABLE_HEADER, summary, table_rows, write_outputs
    from dataclasses import replace

    from opportune.study.simulate import (COUNTING_STRATEGIES, OPTIMAL_BINS, STRATEGIES, StrategyUnavailable, StudyConfig,
                                    StudyError, prepare, run_study)
    from opportune.worlds import CellModel, TimeModel

    if (plan_file is None) == (from_results is None):
        fail("give a plan file, or --from results.json to run a recorded study again (not both)", 2, as_json=as_json)
    if from_results is not None:
        recorded, plan = _recorded_study(from_results, as_json)
        # by name: typer carries its own copy of click, whose enum is not the click package's
        given = {name for name in ctx.params if getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"}
    else:
        plan = load_or_exit(plan_file, json_errors=as_json)
    sim = plan.simulation
    chosen_bin = bin_model or sim.get("bin", "uniform")
    explicit = strategies is not None
    names = [s.strip() for s in (strategies or "").split(",") if s.strip()] if explicit else \
        [s for s in STRATEGIES if s != "optimal" or (chosen_bin in OPTIMAL_BINS and plan.n_units <= OPTIMAL_DEFAULT_UNITS)]
    if not explicit and chosen_bin in OPTIMAL_BINS and plan.n_units > OPTIMAL_DEFAULT_UNITS:
        _err().print(f"note: 'optimal' left out: its state space grows exponentially and {plan.n_units} parts is "
                     f"beyond the default ({OPTIMAL_DEFAULT_UNITS}); ask for it with --strategies to try anyway")
    if explicit and not names:
        fail("--strategies is empty: name at least one of " + ", ".join(STRATEGIES), 2)
    names = _current_names(names)
    try:
        if from_results is not None:
            # The recorded study, with what this command line says instead where it says something.
            explicit = True   # the recorded strategies, all of them: none is quietly left out this time
            config = StudyConfig.from_settings(plan, recorded)
            overrides = {key: value for key, value in (
                ("strategies", tuple(dict.fromkeys(names))), ("trials", trials), ("seed", seed),
                ("bin", bin_model), ("visible", visible), ("buffer_capacity", buffer_capacity),
                ("training_runs", training_runs), ("optimal_states", optimal_states),
                ("count_time_limit", count_time_limit), ("decision_budget", decision_budget))
                if {"bin": "bin_model"}.get(key, key) in given}
            cost = {k: v for k, v in (("motion", motion_cost), ("shake", shake_cost), ("look", look_cost))
                    if f"{k}_cost" in given}
            if cost:
                overrides["costs"] = replace(config.costs, **cost)
            config = replace(config, **overrides).validate()
        else:
            costs = TimeModel.from_plan(plan, motion=motion_cost, shake=shake_cost, look=look_cost)
            config = StudyConfig(
                cell=CellModel.from_plan(plan),
                plan=plan, strategies=tuple(dict.fromkeys(names)), trials=trials, seed=seed, bin=chosen_bin,
                visible=visible or sim.get("visible", 2),
                buffer_capacity=buffer_capacity if buffer_capacity is not None else sim.get("buffer_capacity"),
                costs=costs, training_runs=training_runs, optimal_states=optimal_states,
                count_time_limit=count_time_limit if count_time_limit is not None else (10.0 if explicit else 2.0),
                decision_budget=decision_budget,
            ).validate()
        if bound and config.bin not in BOUND_BINS:   # before the study: refused at once, not after it
            fail(f"--bound is defined for the {' and '.join(BOUND_BINS)} bins, not '{config.bin}': "
                 "leave --bound out or change --bin", 2, as_json=as_json)
        if bound:
            _check_bound(config, penalty or "auto", as_json)
        while True:
            try:
                prepared = prepare(config)
                break
            except StrategyUnavailable as exc:
                if (exc.strategy in COUNTING_STRATEGIES and config.decision_budget is None
                        and decision_budget is None and from_results is None):
                    # A plan too large to count every look exactly in reasonable time (ARC111): the counting
                    # policies decide within the sequencer's budget instead of being left out, and say so.
                    from opportune.sequencer import DEFAULT_BUDGET

                    config = replace(config, decision_budget=DEFAULT_BUDGET)
                    decision_budget = DEFAULT_BUDGET
                    _err().print(f"note: the exact counts of {plan.name}'s first look take longer than "
                                 f"{config.count_time_limit:g} s: the counting policies decide within "
                                 f"{1000 * DEFAULT_BUDGET:g} ms per decision, exact where the counts fit and "
                                 "estimated elsewhere (set --decision-budget to choose)")
                    continue
                if explicit or len(config.strategies) == 1:
                    raise
                _err().print(f"note: {exc} — leaving '{exc.strategy}' out")
                config = replace(config, strategies=tuple(s for s in config.strategies if s != exc.strategy))
        progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                            TimeRemainingColumn(), console=_err(), disable=not _err().is_terminal, transient=True)
        with progress:
            task = progress.add_task("simulating", total=trials * len(config.strategies))
            result = run_study(config, workers=workers, dask_address=dask, prepared=prepared,
                               progress=lambda s, n: progress.advance(task, n))
    except (StudyError, ValueError) as exc:
        fail(str(exc))
    doc = summary(result)
    if bound:
        doc["bound"] = _study_bound(config, doc, penalty or "auto", as_json)
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
    if as_json:
        print(json.dumps(doc, indent=2))
    else:
        cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
        table = Table(title=f"{plan.name}: {config.bin} bin, {config.visible} visible, buffer {cap}, "
                            f"{doc['trials']:,} trials, seed {config.seed}")
        for i, col in enumerate(TABLE_HEADER):
            table.add_column(col, justify="left" if i == 0 else "right")
        for row in table_rows(doc):
            table.add_row(*row)
        _out().print(table)
        if result.prepared.optimal_start is not None:
            _out().print(f"optimal expected time (exact): {result.prepared.optimal_start:.4f} "
                         f"({result.prepared.optimal_states:,} states, {result.prepared.optimal_seconds:.1f} s)")
        paired = [(name, s["paired"]) for name, s in doc["strategies"].items() if "paired" in s]
        if paired:
            _out().print(f"paired with {paired[0][1]['with']} on the same bins (mean difference of time, 95% interval): "
                         + "; ".join(f"{name} {p['mean_difference']:+.3f} ({p['ci95'][0]:+.3f} .. {p['ci95'][1]:+.3f})"
                                     for name, p in paired))
        if bound:
            _out().print(_bound_line(doc["bound"]))
        for note in doc["notes"]:
            _out().print(f"note: {note}")
        budgeted = [s for s in config.strategies if s in COUNTING_STRATEGIES]
        if decision_budget is not None and budgeted:
            _out().print(f"note: {', '.join(budgeted)} decided within {1000 * decision_budget:g} ms per decision "
                         "(estimated where exact counts did not fit): "
                         f"{'its' if len(budgeted) == 1 else 'their'} numbers depend on this machine's speed")
        if out_dir:
            _out().print(f"wrote {', '.join(str(p) for p in written)}")
        if report_file:
            _out().print(f"wrote the report: {report_file}")
    if result.interrupted:
        _err().print("interrupted: the table shows the trials that finished")
        raise typer.Exit(130)


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


def _check_bound(config, penalty: str, as_json: bool) -> None:
    """Refuse a bound that cannot be computed as asked before the study runs (the optimum's penalty on a plan
    too large for it is counted, within 2 s, not solved)."""
    from opportune.study.bounds import BoundError, check_request

    try:
        check_request(config.plan, **_bound_settings(config, penalty))
    except BoundError as exc:
        fail(f"--bound: {exc}", 2, as_json=as_json)


def _study_bound(config, doc: dict, penalty: str, as_json: bool) -> dict:
    """``simulate --bound``: the certified lower bound on the study's world, and each policy's mean against it."""
    from opportune.study.bounds import BoundError, lower_bound, policy_gaps

    try:
        r = lower_bound(config.plan, seed=config.seed, costs=config.costs, **_bound_settings(config, penalty))
    except BoundError as exc:
        fail(f"--bound: {exc}", 2, as_json=as_json)
    out = r.to_dict()
    out["policies"] = policy_gaps(r, {name: s["time"] for name, s in doc["strategies"].items()})
    return out


def _bound_line(b: dict) -> str:
    """The bound, each policy's mean against it (a signed gap in words), and what a mean below it means."""
    from opportune.study.bounds import describe_gaps

    return (f"lower bound on any online policy's expected time (certified: {b['method']}): "
            f"{b['mean']:.3f} ± {b['half_width']:.3f} (95%); each policy's mean against it: "
            + describe_gaps(b["policies"]))


# The programmes' speed, measured in CPU time on a 2-core machine: the optimum's states (as estimated
# before the start) per second of the whole evaluation (the policy's programme and the optimum's), about
# 500-1,000/s in a Markov bin on plans of 11-21 parts (a state costs a look-up per look, ~r²/2 looks with r
# parts left) and 4,000-10,000/s in the pile (whose windows are stored several at once).  They set the
# default of --max-states (about a minute) and the time a refusal quotes.
EVALUATE_STATES_PER_SECOND = {"uniform": 500, "weighted": 500, "pile": 4_000}
EVALUATE_MAX_STATES = 30_000


@app.command()
def evaluate(
    plan_file: Path = PLAN_ARG,
    policy: str = typer.Option("lookahead", "--policy",
                               help="The policy to evaluate: lookahead (the default policy), paper "
                                    "(the paper's rule), bin-first, slack, rollout, buffer, shake or quantify"),
    bin_model: Optional[str] = typer.Option(None, "--bin", help="uniform, weighted or pile (default: plan, else uniform)"),
    visible: Optional[int] = typer.Option(None, "--visible", min=1, help="Parts seen per look (default: plan, else 2)"),
    buffer_capacity: Optional[int] = typer.Option(None, "--buffer-capacity", min=0, max=MAX_BUFFER,
                                                  help="Buffer locations (default: plan, else unlimited)"),
    max_states: int = typer.Option(
        EVALUATE_MAX_STATES, "--max-states", min=1,
        help=f"Most states of the dynamic programme (default {EVALUATE_MAX_STATES:,}: about a minute at the "
             f"~{EVALUATE_STATES_PER_SECOND['uniform']:,} states/s measured on a 2-core machine (seconds on plans of "
             "10 parts, up to two minutes of CPU on plans of 45; the pile bin is ~8 times faster), and at most "
             f"about {2 * EVALUATE_MAX_STATES * 1_000 // 10**6 + 30} MB).  The states a plan needs are counted or "
             "estimated before the programme starts, and a plan over the limit is refused at once"),
    time_limit: Optional[float] = typer.Option(None, "--time-limit", min=0.0,
                                               help="Stop the programme after this many seconds and say how far it "
                                                    "got (default: none; --max-states bounds the work)"),
    without_optimum: bool = typer.Option(False, "--without-optimum",
                                         help="The default policy (lookahead) with its exact optimum switched off: "
                                              "it decides by its fallback (the exact optimum of a frontier window of "
                                              "the plan, the rest lumped, in its bin), measured against the optimum"),
    as_json: bool = json_option(),
):
    """Exact expected cost of a policy and of the optimum (a dynamic programme, no Monte Carlo error).

    The states the programme needs are counted (or estimated, on large plans) first: a plan over --max-states is
    refused before any work, with the figure.  On a terminal a progress bar shows states done / expected."""
    from opportune.engine import OrderEngine
    from opportune.engine.deadline import Deadline
    from opportune.policies.evaluate import PolicyEvaluator, PolicyStuck
    from opportune.policies.optimal import LOOK_CACHE_LOOKS, OptimalTooLarge, OutOfTime
    from opportune.policies.states import BYTES_PER_STATE, big, estimate_states
    from opportune.study.simulate import (ALL_STRATEGIES, OPTIMAL_BINS, StrategyUnavailable, StudyConfig, StudyError,
                                    make_policy, prepare)
    from opportune.worlds import TimeModel

    plan = load_or_exit(plan_file, json_errors=as_json)
    sim = plan.simulation
    chosen_bin = bin_model or sim.get("bin", "uniform")
    if chosen_bin not in OPTIMAL_BINS:
        fail(f"exact evaluation is defined for the uniform, weighted and pile bins, not '{chosen_bin}': use "
             f"`opportune simulate --bin {chosen_bin}` for a Monte Carlo estimate", 2)
    unsuitable = ("optimal", "random", "pallet", "kitting")
    policy = _current_names([policy])[0]
    if policy not in ALL_STRATEGIES or policy in unsuitable:
        fail(f"unknown or unsuitable policy '{policy}': choose from "
             f"{', '.join(s for s in ALL_STRATEGIES if s not in unsuitable)} (the optimum is printed beside it; "
             "random has no single decision rule; pallet and kitting do not draw from the bin)", 2)
    if without_optimum and policy != "lookahead":
        fail(f"--without-optimum switches off the exact optimum of the default policy (lookahead); '{policy}' has "
             "none: drop the option, or use --policy lookahead", 2, as_json=as_json)
    simulate_hint = f"`opportune simulate{' --bin pile' if chosen_bin == 'pile' else ''}`"
    try:
        config = StudyConfig(plan=plan, strategies=(policy,), trials=1, bin=chosen_bin,
                             visible=visible or sim.get("visible", 2),
                             buffer_capacity=buffer_capacity if buffer_capacity is not None else sim.get("buffer_capacity"),
                             costs=TimeModel.from_plan(plan), optimal_states=max_states).validate()
    except (StudyError, ValueError) as exc:
        fail(str(exc))
    engine = OrderEngine(plan)
    # how many states, before any: a few seconds at most, and far cheaper per state than the programme
    estimate = estimate_states(engine, visible=config.visible, capacity=config.buffer_capacity,
                               pile=chosen_bin == "pile", stop_above=max_states, time_limit=3.0)
    if estimate.looks > LOOK_CACHE_LOOKS:
        fail(f"the exact evaluation of {plan.name} would weigh {estimate.looks:,} distinct looks at every state "
             f"({plan.n_units:,} parts, {config.visible} visible), more than the {LOOK_CACHE_LOOKS:,} the programme "
             f"keeps: it is out of reach whatever --max-states; estimate it by Monte Carlo with {simulate_hint}")
    if estimate.over(max_states):
        figure = max(estimate.states, estimate.low)
        rate = EVALUATE_STATES_PER_SECOND[chosen_bin]
        fail(f"the exact evaluation of {plan.name} needs {estimate.describe()} states, more than --max-states "
             f"{max_states:,} (at ~{rate:,} states/s that is {_duration(figure / rate)}, and about "
             f"{big(2 * figure * BYTES_PER_STATE // 10**6)} MB): raise --max-states, reduce --buffer-capacity or "
             f"--visible, or estimate it by Monte Carlo with {simulate_hint}")
    until = Deadline.after(time_limit)
    ev = optimum = None
    policy_bound, ordered, by_optimum = estimate.states, False, False
    try:
        chosen = make_policy(policy, engine, config, prepare(config, engine))
        if without_optimum:
            chosen.optimal = False      # the look-ahead's own setting: its fallback decides
        settings = dict(visible=config.visible, capacity=config.buffer_capacity, costs=config.costs,
                        max_states=max_states)
        if chosen_bin == "pile":
            from opportune.policies.pile import PileSolver, pile_solver

            # the optimum compiled where the core is built (the same values): the policy's programme in Python
            ev, optimum = PileSolver(engine, chosen, **settings), pile_solver(engine, **settings)
            if estimate.exact:
                optimum.reserve(estimate.states)    # a compiled table sized at once: it never doubles
        else:
            ev = PolicyEvaluator(engine, chosen, weights=config.weights if chosen_bin == "weighted" else None,
                                 **settings)
        ev.deadline = until         # finding where the buffer's order decides counts options: within it too
        # a policy deciding by the optimum is worth the optimum: none of its own states are evaluated
        by_optimum = chosen_bin != "pile" and ev.takes_optimum()
        policy_bound, ordered = (0, False) if by_optimum else (ev.states_bound(estimate.states), ev.ordered)
        kept = " (its buffer kept in the order of buffering)" if ordered else ""
        if not as_json and by_optimum:
            _out().print(f"states: {estimate.describe()} for the optimum; none for the policy (it decides by the "
                         "optimum's values: its value is the optimum's)")
        elif not as_json:
            # a bound, not a count: the policy reaches a part of these states (it stops at --max-states if not)
            _out().print(f"states: {estimate.describe()} for the optimum, at most {big(policy_bound)} for the "
                         f"policy{kept}" + (f"; it stops if it passes --max-states {max_states:,}"
                                            if policy_bound > max_states else ""))
        with _evaluation_progress(estimate, enabled=not as_json) as report:
            for solver in {id(ev): ev, id(optimum): optimum}.values():
                if solver is not None:
                    solver.deadline, solver.progress = until, report
            if hasattr(chosen, "deadline"):    # a policy with a programme of its own (the look-ahead) stops too
                chosen.deadline = until
            if chosen_bin == "pile":
                value = ev.value()
                report(ev, done=True)
                best = optimum.value()
                states, policy_states = optimum.states, ev.states
            else:
                value = ev.value()
                report(ev, done=True)
                best = ev.optimal()
                states, policy_states = ev.states, ev.policy_states
    except (OptimalTooLarge, OutOfTime) as exc:
        why = (f"passed --time-limit {time_limit:g} s" if isinstance(exc, OutOfTime)
               else f"needed more than --max-states {max_states:,} states")
        bound = (f", at most {big(policy_bound)} for the policy" if policy_bound not in (0, estimate.states)
                 else "")
        fail(f"the exact evaluation of {plan.name} {why}: it stopped after {_how_far(ev, optimum, chosen_bin)} of "
             f"{estimate.describe()} expected for the optimum{bound}; raise the limit, or estimate it by Monte Carlo "
             f"with {simulate_hint}")
    except StrategyUnavailable:
        fail(f"the exact evaluation of {plan.name} ({plan.n_units} parts) is out of reach: the policy's first "
             "decision alone does not finish in 10 s, and the states to evaluate grow exponentially with the parts "
             "(up to --max-states); estimate it with `opportune simulate --strategies "
             f"{policy} --decision-budget 0.05`")
    except (PolicyStuck, StudyError, ValueError) as exc:
        fail(str(exc))
    doc = {"plan": plan.name, "policy": policy, "bin": chosen_bin, "visible": config.visible,
           "buffer_capacity": config.buffer_capacity, "expected_time": value, "optimal": best,
           "ratio": value / best if best else None, "states": states, "policy_states": policy_states,
           "estimated_states": estimate.states, "estimate_exact": estimate.exact,
           "estimated_policy_states": policy_bound, "buffer_order_kept": ordered,
           "policy_by_optimum": bool(getattr(ev, "by_optimum", False)), "without_optimum": without_optimum}
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
    _out().print(f"{plan.name}: {chosen_bin} bin, {config.visible} visible, buffer {cap}")
    _out().print(f"  {policy}{' (its exact optimum switched off)' * without_optimum}: expected time {value:.4f}")
    _out().print(f"  optimum: expected time {best:.4f}")
    reached = ("the policy decides by the optimum's values, so its value is the optimum's"
               if doc["policy_by_optimum"] else f"{policy_states:,} reached by the policy")
    _out().print(f"  ratio {value / best:.5f} ({100 * (value / best - 1):+.2f}%); "
                 f"{states:,} states for the optimum, {reached}")


def _duration(seconds: float) -> str:
    """``'40 s'``, ``'12 min'``, ``'3.5 h'``, ``'2.1e+05 years'``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 86400 * 365:
        return f"{seconds / 3600:.1f} h"
    years = seconds / (86400 * 365)
    return f"{years:,.0f} years" if years < 1e6 else f"{years:.1e} years"


def _how_far(ev, optimum, chosen_bin: str) -> str:
    """States done by the policy's programme and the optimum's, in words."""
    if ev is None:
        return "no states"
    if chosen_bin == "pile":
        done = [("the policy's", ev.states), ("the optimum's", optimum.states if optimum is not None else 0)]
    else:
        done = [("the policy's", ev.policy_states), ("the optimum's", ev.states)]
    return " and ".join(f"{n:,} of {who}" for who, n in done) + " states"


class _evaluation_progress:
    """A rich progress bar of states done / expected, on a terminal (standard output and error) and not under
    ``--json``; otherwise a no-op.  Used as ``with ... as report``; ``report(solver)`` every 64 new states,
    ``report(solver, done=True)`` when the policy's programme has finished (it reaches fewer states)."""

    def __init__(self, estimate, *, enabled: bool):
        self.estimate = estimate
        self.enabled = enabled and _out().is_terminal and _err().is_terminal
        self.bar = None
        self.tasks: dict[str, int] = {}

    def __enter__(self):
        if self.enabled:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("states"), TimeElapsedColumn(), console=_err(), transient=True)
            self.bar.__enter__()
            total = max(1, self.estimate.states)
            self.tasks = {"policy": self.bar.add_task("policy ", total=total),
                          "optimum": self.bar.add_task("optimum", total=total)}
        return self.report

    def report(self, solver, done: bool = False) -> None:
        if self.bar is None:
            return
        from opportune.policies.evaluate import PolicyEvaluator

        if isinstance(solver, PolicyEvaluator):
            counts = {"policy": solver.policy_states, "optimum": solver.states}
        else:
            counts = {"policy" if solver.policy is not None else "optimum": solver.states}
        for name, n in counts.items():
            if done and name == "policy":
                self.bar.update(self.tasks[name], completed=n, total=max(1, n))
            else:
                self.bar.update(self.tasks[name], completed=n)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.__exit__(*exc)
        return False


@app.command()
def examples(as_json: bool = json_option()):
    """List the examples and data sets shipped with the package (use them as example:NAME, salbp:NAME)."""
    from opportune import datasets

    rows = [{"name": f"example:{name}", "kind": kind, "about": about} for name, kind, about in datasets.examples()]
    rows += [{"name": f"salbp:{name}", "kind": "plan", "about": "SALBP precedence graph (Scholl's benchmark data)"}
             for name in datasets.salbp_names()]
    if as_json:
        print(json.dumps(rows, indent=2))
        return
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        _out().print(f"{_escape(r['name']):<{width}}  {r['kind']:<9}  {_escape(r['about'])}")
    _out().print("e.g. opportune replay example:gearbox example:gearbox-table1; opportune count salbp:KILBRID")


@app.command()
def convert(
    plan_file: Path = PLAN_ARG,
    output: Path = typer.Argument(..., help="Output file: .yaml, .json, .graphml, .dot or .alb ('-' for standard "
                                            "output with --to)", show_default=False),
    to: Optional[str] = typer.Option(None, "--to", help="yaml, json, graphml, dot or alb (default: from the suffix)"),
    as_json: bool = json_option("Machine-readable output: what was written, {plan, format, wrote}, or with -, "
                                "the converted text as {plan, format, text} (errors too: {\"error\": {...}})"),
):
    """Write a plan in another format (a GraphML or DOT file holds one strategy per graph; .alb one strategy)."""
    import yaml

    from opportune.formats.alb import alb_text
    from opportune.formats.graphfiles import to_dot_precedence, to_graphml

    plan = load_or_exit(plan_file, json_errors=as_json)
    fmt = (to or output.suffix.lstrip(".")).lower().replace("yml", "yaml").replace("gv", "dot")
    writers = {"yaml": lambda: yaml.safe_dump(plan.to_dict(), sort_keys=False, allow_unicode=True),
               "json": lambda: json.dumps(plan.to_dict(), indent=2, ensure_ascii=False) + "\n",
               "graphml": lambda: to_graphml(plan), "dot": lambda: to_dot_precedence(plan),
               "alb": lambda: alb_text(plan)}
    if fmt not in writers:
        fail(f"unknown output format '{fmt or output}': use .yaml, .json, .graphml, .dot or .alb (or --to)", 2)
    if fmt in ("dot", "alb") and len(plan.strategies) > 1:
        fail(f"{plan.name} has {len(plan.strategies)} strategies and a .{fmt} file holds one: write .yaml, .json "
             "or .graphml (one graph per strategy)", 2)
    try:
        text = writers[fmt]()
    except ValueError as exc:
        fail(str(exc))
    if fmt == "alb" and not as_json:        # what the format cannot hold is said, not silently dropped
        shown = ", ".join(f"{i} = {p}" for i, p in enumerate(plan.part_ids[:4], 1))
        more = ", ..." if len(plan.parts) > 4 else ""
        _err().print(_escape(f"note: an .alb file numbers its tasks: the parts are 1 to {len(plan.parts)} in their "
                             f"order in the plan ({shown}{more}); the plan's name and the parts' names are not "
                             "kept"))
    if str(output) == "-":
        if as_json:
            print(json.dumps({"plan": plan.name, "format": fmt, "text": text}, indent=2))
        else:
            sys.stdout.write(text)
        return
    _write_text(output, text)
    if as_json:
        print(json.dumps({"plan": plan.name, "format": fmt, "wrote": str(output)}, indent=2))
    else:
        _out().print(f"wrote {_escape(str(output))}")

@app.command()
def schema():
    """Print the JSON Schema of plan files."""
    from opportune.formats.validate import plan_schema

    print(json.dumps(plan_schema(), indent=2))


from opportune.service.commands import register as _register_service
_register_service(app)


# >>> issue 15: and-or (command lives here)
# <<< issue 15: and-or


# >>> issue 15: products (command lives here)
_NOT_WITH_PRODUCTS = ("from_results", "workers", "dask", "out_dir", "training_runs", "optimal_states",
                      "count_time_limit")


def _simulate_products(ctx: typer.Context, plan_file: Optional[Path], products: int, *, strategies, trials, seed,
                       bin_model, visible, buffer_capacity, as_json, motion_cost, shake_cost, look_cost,
                       decision_budget) -> None:
    """``simulate PLAN --products N``: N fixtures from one bin, against N cells and one product after another."""
    given = [name for name in _NOT_WITH_PRODUCTS
             if getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"]
    if given:
        flag = {"from_results": "--from", "out_dir": "--out"}.get(given[0], "--" + given[0].replace("_", "-"))
        fail(f"{flag} does not apply with --products (the multi-product study runs in this process and prints "
             "its table, or --json)", 2, as_json=as_json)
    if plan_file is None:
        fail("give a plan file to build several products of", 2, as_json=as_json)
    from rich.table import Table

    from opportune.planning.products import ProductsError
    from opportune.study.simulate_products import MODE_LABELS, ProductsConfig, copies, run_products
    from opportune.worlds import TimeModel

    plan = load_or_exit(plan_file, json_errors=as_json)
    sim = plan.simulation
    policies = tuple(_current_names(s.strip() for s in (strategies or "paper,lookahead").split(",") if s.strip()))
    if not policies:
        fail("--strategies is empty: name at least one policy, e.g. paper,lookahead", 2, as_json=as_json)
    try:
        config = ProductsConfig(
            copies(plan, products), policies=policies, trials=trials, seed=seed,
            bin=bin_model or sim.get("bin", "uniform"), visible=visible or sim.get("visible", 2),
            buffer_capacity=buffer_capacity if buffer_capacity is not None else sim.get("buffer_capacity"),
            costs=TimeModel.from_plan(plan, motion=motion_cost, shake=shake_cost, look=look_cost),
            decision_budget=decision_budget).validate()
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                            TimeRemainingColumn(), console=_err(), disable=not _err().is_terminal, transient=True)
        with progress:
            task = progress.add_task("simulating", total=trials * len(config.modes) * len(policies))
            result = run_products(config, progress=lambda _mode, _policy, n: progress.advance(task, n))
    except (ProductsError, ValueError) as exc:
        fail(str(exc), as_json=as_json)
    doc = result.summary()
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
    table = Table(title=f"{plan.name} ×{products}: {config.bin} bin, {config.visible} visible, buffer {cap}, "
                        f"{trials:,} trials, seed {seed}; time, buffer moves and shakes per product")
    for i, col in enumerate(("cell", "policy", "time ± 95%", "buffer moves", "shakes", "buffer peak (mean, max)",
                             "buffer mean", "complete")):
        table.add_column(col, justify="left" if i < 2 else "right")
    for row in doc["rows"]:
        t = row["time"]
        table.add_row(MODE_LABELS[row["mode"]].replace("N ", f"{products} "), row["policy"],
                      f"{t['mean']:.2f} ± {t['mean'] - t['ci95'][0]:.2f}",
                      f"{row['buffer_moves']['mean']:.2f}", f"{row['shakes']['mean']:.2f}",
                      f"{row['buffer_peak']['mean']:.2f}, {row['buffer_max']}", f"{row['buffer_mean']['mean']:.2f}",
                      f"{row['complete']}/{row['trials']}")
    _out().print(table)
    modelled = [p for p in policies if p in ("lookahead", "rollout")]
    if products > 1 and modelled:
        _out().print(f"note: with a part kind needed on several fixtures, {' and '.join(modelled)} decide"
                     f"{'s' if len(modelled) == 1 else ''} by the base rule (slack): its model of the bin is "
                     "one product's parts")
# <<< issue 15: products


# >>> issue 15: relax (command lives here)
@app.command()
def relax(
    plan_file: Path = PLAN_ARG,
    output: Optional[Path] = typer.Option(None, "-o", "--output",
                                          help="Write the relaxed plan (YAML) here instead of standard output"),
    installed: Optional[str] = typer.Option(None, "--installed",
                                            help='Parts already installed, in order ("ca ba" or "ca,ba"): the '
                                                 "relaxed plan admits this prefix"),
    time_limit: float = typer.Option(10.0, "--time-limit", min=0.1, max=3600,
                                     help="Seconds for the search; past it, the best relaxation found is "
                                          "written, marked as not proven minimal"),
    as_json: bool = json_option("Machine-readable output: {\"plan\", \"dropped\", \"weight\", \"minimal\"} on "
                                "standard output"),
):
    """Drop the cheapest set of constraints (by weight) that makes an over-constrained plan admissible.

    Reads a plan whose strategies have cycles (YAML or JSON), or that contradicts --installed; writes
    the relaxed plan as YAML and lists the constraints dropped on standard error.
    """
    from opportune.derive.relax import RelaxRefused, constraint_lines
    from opportune.derive.relax import relax as relax_plan
    from opportune.formats.loader import CheckResult, read_plan

    result = read_plan(plan_file, allow_cycles=True)
    if not result.ok:
        if as_json:
            _print_error({"message": f"{plan_file}: not a valid plan ({len(result.errors)} error(s))",
                          "file": str(plan_file), "problems": [p.to_dict() for p in result.problems]}, 1)
        else:
            _print_problems(CheckResult(None, result.errors), _err())
            if all(p.code == "cycle" for p in result.errors):  # cycles in a format read only when acyclic
                _err().print(f"{_escape(str(plan_file))}: `opportune relax` reads plans with cycles from YAML and "
                             "JSON files only: write this one as a YAML plan (parts, requires), then relax it")
            else:
                _err().print(f"{_escape(str(plan_file))}: {len(result.errors)} error(s); `opportune relax` drops "
                             "constraints that form cycles but cannot mend these")
        raise typer.Exit(1)
    plan = result.plan
    prefix = [p for p in (installed or "").replace(",", " ").split() if p]
    try:
        relaxation = relax_plan(plan, prefix, time_limit=time_limit, lines=constraint_lines(plan_file))
    except RelaxRefused as exc:
        fail(f"{plan_file}: {exc}; split the plan, or break the largest knot of constraints by hand")
    except ValueError as exc:
        fail(str(exc))
    text = _plan_yaml(relaxation.plan.to_dict())
    if output is not None:
        _write_text(output, text)
    if as_json:
        print(json.dumps(relaxation.to_dict(), indent=2))
    elif output is None:
        sys.stdout.write(text)
    err = _err()
    if not relaxation.changed:
        state = f" after {' '.join(prefix)}" if prefix else ""
        if not as_json:
            err.print(f"{_escape(plan.name)}: the plan is already admissible{_escape(state)}: nothing to drop; "
                      "the plan is written unchanged")
        return
    if as_json:
        return
    n = len(relaxation.dropped)
    proof = "minimal" if relaxation.minimal else "NOT PROVEN MINIMAL: the search ran out of --time-limit"
    err.print(f"{_escape(plan.name)}: dropped {n} constraint{'s' if n != 1 else ''} of total weight "
              f"{relaxation.weight:g} ({proof}):")
    for d in relaxation.dropped:
        where = f", {plan_file}:{d.line}" if d.line else ""
        why = ", violated by --installed" if d.forced else ""
        err.print(f"  {_escape(d.before)} -> {_escape(d.after)}  (strategy '{_escape(d.strategy)}', weight "
                  f"{d.weight:g}{_escape(where)}{why})")
    if relaxation.repaired is not None and len(plan.strategies) > 1:
        err.print(f"strategy '{_escape(relaxation.repaired)}' was relaxed to admit the installed parts (the cheapest "
                  "to repair); the other strategies are as written")
    for name, same in relaxation.removed:
        err.print(f"strategy '{_escape(name)}' removed: relaxed, it admits exactly the sequences of '{_escape(same)}'")
    if output is not None:
        err.print(f"wrote {_escape(str(output))}")


def _write_text(output: Path, text: str) -> None:
    """Write a command's text file, or exit 1 saying why it cannot be written."""
    try:
        output.write_text(text, encoding="utf-8")
    except OSError as exc:
        fail(f"cannot write {output}: {exc.strerror or exc}")


def _plan_yaml(doc: dict) -> str:
    """A plan document as YAML that reads like a hand-written plan: short lists (parts, requirements)
    and weighted entries on one line each, ``co: [rl, dr, {part: ml, weight: 5}]``."""
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    def flat(value) -> bool:
        return not isinstance(value, (list, dict)) or (isinstance(value, dict) and
                                                        all(not isinstance(v, (list, dict)) for v in value.values()))

    def represent_list(dumper, data):
        return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=all(flat(v) for v in data))

    Dumper.add_representer(list, represent_list)
    return yaml.dump(doc, Dumper=Dumper, sort_keys=False, allow_unicode=True, width=100)
# <<< issue 15: relax


# >>> issue 15: learn (command lives here)
@app.command()
def learn(
    sequences: str = typer.Argument(..., help="Successful sequences: one per line, part ids separated by spaces or "
                                              "commas, # comments; - for standard input; example:NAME for a shipped "
                                              "one (example:gearbox-observed)", show_default=False),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Write the plan (YAML) to this file instead "
                                                                       "of standard output"),
    failed: Optional[str] = typer.Option(None, "--failed", help="Failed sequences (same format and parts): report "
                                                                "the constraints each breaks, and those none can "
                                                                "exclude"),
    name: Optional[str] = typer.Option(None, "--name", help="The plan's name (default: the file's stem)"),
    max_accident: float = typer.Option(0.05, "--max-accident", min=0.0, max=1.0,
                                       help="Flag (in the comments, the JSON and on standard error) the constraints "
                                            "whose accident probability is above this; they stay in the plan"),
    split: bool = typer.Option(False, "--split", help="When failed sequences cannot be excluded by one partial "
                                                      "order, write the two-strategy repair (if found) instead"),
    time_limit: float = typer.Option(20.0, "--time-limit", min=0.1, max=3600.0,
                                     help="Seconds for all the exact counts behind the accident probabilities "
                                          "(those over it are reported as not computed)"),
    as_json: bool = json_option("Machine-readable output: {\"plan\", \"constraints\", \"sequences\", \"failed\", "
                                "\"unexcluded\", \"repair\", ...} on standard output (errors too)"),
):
    """Learn a plan from observed successful sequences: the constraints every sequence satisfies (minimal set),
    each with its support and the probability that it is an accident of too few observations."""
    from opportune.formats.sequences import SequenceError, read_sequences
    from opportune.derive.learn import learn_plan
    from opportune.planning.plan import PlanError

    if name is not None and not name.strip():
        fail("--name: give a non-empty name", 2)
    if failed == "-" and sequences == "-":
        fail("only one of SEQUENCES and --failed can be standard input (-)", 2)
    try:
        good = read_sequences(sequences)
        bad = read_sequences(failed, like=good, what="failed sequences") if failed else ()
        stem = sequences.split(":", 1)[1] if sequences.lower().startswith("example:") else Path(sequences).stem
        learned = learn_plan(good, bad, name=name or (stem if sequences != "-" and stem else "learned"),
                             max_accident=max_accident, time_limit=time_limit)
    except SequenceError as exc:
        fail_problem(exc.problem)
    except PlanError as exc:    # the learned plan is built through the plan checker: say what it found
        fail(f"the learned plan is not valid: {exc}")
    text = learned.to_yaml(repaired=split)
    if output is not None:
        _write_text(output, text)
    if as_json:
        doc = learned.to_json()
        if split and learned.repair is not None:
            doc["written"] = "repair"
        print(json.dumps(doc, indent=2, ensure_ascii=False))
    elif output is None:
        sys.stdout.write(text)
    err = _err()
    n = len(learned.constraints)
    err.print(f"learned {n} constraint{'s' if n != 1 else ''} from {learned.sequences} sequence"
              f"{'s' if learned.sequences != 1 else ''} ({learned.distinct} different)"
              + (f"; wrote {_escape(str(output))}" if output is not None else ""))
    if learned.flagged:
        shown = ", ".join(f"{c.before} -> {c.after} ({c.accident_probability:.2g})" for c in learned.flagged[:20])
        more = f", … ({len(learned.flagged) - 20} more)" if len(learned.flagged) > 20 else ""
        err.print(f"[yellow]warning[/]: {len(learned.flagged)} constraint(s) may be accidents of too few observations "
                  f"(accident probability above {max_accident:g}): {_escape(shown + more)} — kept in the plan; more "
                  "observations would settle them", markup=True)
    if not learned.complete:
        err.print("[yellow]warning[/]: some accident probabilities were not computed within --time-limit "
                  f"{time_limit:g} s (marked 'not computed')", markup=True)
    for f in learned.failed:
        if f.excluded:
            broken = ", ".join(f"{b} -> {a}" for b, a in f.violates)
            err.print(f"{_escape(f.where)}: failed sequence breaks {_escape(broken)} (confirmed)")
    for f in learned.unexcluded:
        why = ("the same sequence is also among the successes" if f.succeeded else
               "it satisfies every learned constraint, so no single partial order that admits all the successes "
               "excludes it")
        err.print(f"[yellow]warning[/]: {_escape(f.where)}: failed sequence cannot be excluded: {_escape(why)}",
                  markup=True)
    if learned.unexcluded:
        hint = "" if split or learned.repair is None else " (--split writes it)"
        err.print(f"  repair: {_escape(learned.repair_note)}{hint}")
# <<< issue 15: learn


@app.command()
def derive(
    assembly: Path = typer.Argument(..., help="The product in its assembled pose: a folder of meshes, one file a part "
                                              "(.obj, .stl, .ply; the part id is the file's stem), a glTF/GLB scene "
                                              "(named nodes), a MuJoCo MJCF model (named bodies) or a STEP file "
                                              "(products; the step extra)",
                                    show_default=False),
    manifest: Optional[Path] = typer.Option(None, "--manifest", help="The assembly's manifest (YAML: names, "
                                                                     "quantities, base, fixture, directions, "
                                                                     "requires); default: assembly.yaml in the folder"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Write the plan (YAML) here instead of "
                                                                       "standard output"),
    directions: Optional[str] = typer.Option(None, "--directions", help="Insertion directions: axes (the six "
                                             "axis directions), or a list such as \"+z,-x,0 0.7 0.7\" (default: the "
                                             "manifest's, else the axes and the normals of the contacts between parts)"),
    gravity: Optional[str] = typer.Option(None, "--gravity", help="Gravity's direction (e.g. -z): each part after "
                                          "the first rests on a part below it that it touches, or on the fixture"),
    connected: bool = typer.Option(False, "--connected", help="Each part after the first touches a part already in"),
    base: Optional[str] = typer.Option(None, "--base", help="The part that goes first"),
    tolerance: Optional[float] = typer.Option(None, "--tolerance", min=0.0,
                                              help="Penetration tolerance in the files' units: parts may overlap by "
                                                   "this much (default: a millionth of the assembly's size)"),
    units: str = typer.Option("m", "--units", help="The files' unit of length: m or mm"),
    explain: bool = typer.Option(False, "--explain", help="Print why the plan is as it is instead of the plan: each "
                                                          "forced order with the part in the way, the parts with one "
                                                          "insertion direction, the count, and what would free the most"),
    figure: Optional[Path] = typer.Option(None, "--figure", help="Draw the exploded view (.png, .svg or .pdf): each "
                                                                 "part moved out along its insertion direction, coloured "
                                                                 "by stage"),
    strategy: int = typer.Option(1, "--strategy", min=1, help="The strategy the figure explodes (from 1)"),
    as_json: bool = json_option("Machine-readable output: {\"parts\", \"directions\", \"blocking_checks\", "
                                "\"strategies\", \"blockers\", ...} on standard output (errors too)"),
):
    """Derive the plan of an assembly from its parts' shapes: exactly the sequences in which each part can go in
    by one straight translation along one of the directions, never through another part.

    Refuses (exit 1) an unusable mesh (naming the part), an assembly with no feasible sequence (naming the parts
    that lock each other) and one whose exact plan needs more strategies than a plan holds.
    """
    try:
        from opportune.derive import DeriveError, GeometryError, ManifestError
        from opportune.derive import derive as derive_plan
    except ImportError as exc:   # trimesh missing: the geometry extra
        fail(f"opportune derive needs the geometry extra: pip install 'opportune[geometry]' ({exc})")
    try:
        derived = derive_plan(assembly, directions=directions, tolerance=tolerance, units=units, gravity=gravity,
                              connected=connected, base=base, manifest=manifest)
    except (GeometryError, DeriveError, ManifestError) as exc:
        fail(str(exc))
    from opportune.derive.show import show

    try:   # before the plan is written: a figure that cannot be drawn leaves no plan file behind
        shown = show(derived, explain=explain, figure=figure, strategy=strategy)
    except (ValueError, OSError) as exc:
        fail(str(exc))
    text = _plan_yaml(derived.plan.to_dict())
    if output is not None:
        _write_text(output, text)
    if as_json:
        print(json.dumps({"plan": derived.plan.to_dict(), **derived.to_dict(), **shown.data}, indent=2,
                         ensure_ascii=False))
        return
    if explain:
        sys.stdout.write(shown.text)
    elif output is None:
        sys.stdout.write(text)
    for note in shown.notes:
        _err().print(f"[yellow]note[/]: {_escape(note)}", markup=True)
    d = derived.to_dict()
    _err().print(_escape(f"{derived.plan.name}: {d['parts']} parts, {len(d['directions'])} directions, "
                         f"{d['blocking_checks']:,} blocking checks, {d['strategies']} strateg"
                         f"{'y' if d['strategies'] == 1 else 'ies'}, {d['constraints']} constraints, "
                         f"{d['cpu_seconds']:.2f} s CPU" + (f"; wrote {output}" if output is not None else "")))


@app.command()
def completion(shell: str = typer.Argument(..., help="bash, zsh, fish or powershell", show_default=False)):
    """Print the shell's completion script: add `eval "$(opportune completion bash)"` to ~/.bashrc (zsh: the
    same in ~/.zshrc; fish: `opportune completion fish > ~/.config/fish/completions/opportune.fish`)."""
    from typer.completion import get_completion_script

    shells = ("bash", "zsh", "fish", "powershell", "pwsh")
    if shell not in shells:
        fail(f"no completion for the shell '{shell}': choose {', '.join(shells[:-1])}", 2)
    print(get_completion_script(prog_name="opportune", complete_var=COMPLETE_VAR, shell=shell))


# The shell asks for completions by running the command with this variable set.  typer's completion classes
# are registered only then, so a normal run never pays for them (add_completion=True doubled the start-up).
COMPLETE_VAR = "_OPPORTUNE_COMPLETE"


def main() -> None:  # console script entry point
    import os

    if COMPLETE_VAR in os.environ:
        from typer.completion import completion_init

        completion_init()
    if "--json" not in sys.argv[1:]:
        app(prog_name="opportune", complete_var=COMPLETE_VAR)
        return
    # Under --json a usage error (a bad option value, a missing argument) is JSON too, with click's exit code.
    # (typer carries its own copy of click: its exceptions are recognised by what they have, not their class)
    try:
        code = app(prog_name="opportune", complete_var=COMPLETE_VAR, standalone_mode=False)
    except Exception as exc:
        if type(exc).__name__ == "Abort":   # Ctrl-C at a prompt
            raise SystemExit(130) from None
        if not (hasattr(exc, "format_message") and isinstance(getattr(exc, "exit_code", None), int)):
            raise
        _print_error({"message": exc.format_message()}, exc.exit_code)
        raise SystemExit(exc.exit_code) from None
    raise SystemExit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
