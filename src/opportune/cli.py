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
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from opportune.formats import CheckResult, read_plan
from opportune.plan import Plan

app = typer.Typer(
    name="opportune",
    help="Least-commitment planning, scheduling and opportunistic execution (Fox & Kempf).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
out = Console(highlight=False, soft_wrap=True)
err = Console(stderr=True, highlight=False, soft_wrap=True)

PLAN_ARG = typer.Argument(..., help="Plan file: .yaml, .json or SALBP .IN2", show_default=False)


def fail(message: str, code: int = 1) -> None:
    err.print(f"[bold red]error:[/] {message}", markup=True)
    raise typer.Exit(code)


def _print_problems(result: CheckResult, console: Console) -> None:
    for p in result.problems:
        colour = "red" if p.severity == "error" else "yellow"
        where = f"{p.where}: " if p.where else ""
        hint = f" [dim]— {_escape(p.hint)}[/]" if p.hint else ""
        console.print(f"{_escape(where)}[{colour}]{p.severity}[/]: {_escape(p.message)}{hint}")


def _escape(text: str) -> str:
    from rich.markup import escape

    return escape(text)


def load_or_exit(path: Path, *, json_errors: bool = False) -> Plan:
    """Load a plan, or print every error and exit 1."""
    result = read_plan(path)
    if not result.ok:
        if json_errors:
            print(json.dumps({"file": str(path), "valid": False,
                              "problems": [p.to_dict() for p in result.problems]}, indent=2))
        else:
            _print_problems(CheckResult(None, result.errors), err)
            err.print(f"{path}: {len(result.errors)} error(s); run `opportune check {path}` for details")
        raise typer.Exit(1)
    return result.plan


# ---------------------------------------------------------------- check


@app.command()
def check(plan_file: Path = PLAN_ARG, as_json: bool = typer.Option(False, "--json", help="Machine-readable output")):
    """Validate a plan: exit 0 with a summary, or 1 with every problem found."""
    from opportune.formats.summary import summarize

    result = read_plan(plan_file)
    summary = summarize(result.plan) if result.ok else None
    if as_json:
        doc = {"file": str(plan_file), "valid": result.ok, "problems": [p.to_dict() for p in result.problems]}
        if summary:
            doc.update(summary)
        print(json.dumps(doc, indent=2))
        raise typer.Exit(0 if result.ok else 1)
    if not result.ok:
        _print_problems(result, out)
        n = len(result.errors)
        out.print(f"[red]{plan_file}: invalid[/] — {n} error{'s' if n != 1 else ''}"
                  + (f", {len(result.warnings)} warning(s)" if result.warnings else ""))
        raise typer.Exit(1)
    s = summary
    out.print(f"[bold]{_escape(s['plan'])}[/] ({_escape(str(plan_file))}): [green]valid[/]")
    units = f" ({s['units']} units)" if s["units"] != s["parts"] else ""
    out.print(f"  parts: {s['parts']}{units}; strategies: {len(s['strategies'])}")
    for st in s["strategies"]:
        out.print(f"  strategy '{_escape(st['name'])}': {st['declared']} constraints declared, "
                  f"{len(st['minimal'])} minimal, {st['implied']} implied in all (transitive closure)")
        text = ", ".join(f"{a} -> {b}" for a, b in st["minimal"]) or "(none: any order)"
        out.print(f"    minimal constraints: {_escape(text)}", crop=False)
    if result.warnings:
        out.print(f"  {len(result.warnings)} warning(s):")
        _print_problems(result, out)


# ---------------------------------------------------------------- count


@app.command()
def count(
    plan_file: Path = PLAN_ARG,
    after: Optional[str] = typer.Option(None, "--after", help='Parts installed first, in order: "ca ba" or "ca,ba"'),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable output"),
    time_limit: float = typer.Option(10.0, "--time-limit", help="Seconds for an exact count before estimating"),
    max_memo: int = typer.Option(2_000_000, "--max-memo", help="Memo entries for an exact count before estimating"),
):
    """Count the admissible sequences of a plan (exact integer; an estimate, marked so, only over budget)."""
    from opportune.engine import NotAdmissible, OrderEngine, Schedule

    plan = load_or_exit(plan_file, json_errors=as_json)
    prefix = [p for p in (after or "").replace(",", " ").split() if p]
    engine = OrderEngine(plan, max_memo=max_memo, time_limit=time_limit)
    sched = Schedule(engine)
    for i, part in enumerate(prefix):
        try:
            sched = sched.install(part)
        except NotAdmissible as exc:
            done = " ".join(prefix[:i]) or "nothing"
            fail(f"--after: {exc} (after installing {done}); the prefix is not admissible")
    result = sched.count_result(time_limit=time_limit)
    if as_json:
        doc = {
            "plan": plan.name,
            "parts": len(plan.parts),
            "strategies": len(plan.strategies),
            "after": prefix,
            "sequences": str(result.value) if result.exact else f"{result.value:.6e}",
            "log10": round(result.log10, 6),
            "exact": result.exact,
        }
        if not result.exact:
            doc.update(rel_error=result.rel_error, confidence=result.confidence, method=result.method)
        print(json.dumps(doc, indent=2))
        return
    state = f" after {' '.join(prefix)}" if prefix else ""
    if result.exact:
        out.print(f"{_escape(plan.name)}{state}: {result.value} admissible sequences (log10 {result.log10:.3f})")
    else:
        out.print(f"{_escape(plan.name)}{state}: about {result.value:.4e} admissible sequences "
                  f"(log10 {result.log10:.3f}) — ESTIMATE, ±{100 * result.rel_error:.2f}% at "
                  f"{100 * result.confidence:.0f}% confidence ({result.method}); the exact count exceeded the budget")


# ---------------------------------------------------------------- graph


@app.command()
def graph(
    plan_file: Path = PLAN_ARG,
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Output file: .svg, .png, .pdf or .dot"),
    fmt: Optional[str] = typer.Option(None, "--format", help="svg, png, pdf or dot (default: from the -o suffix)"),
):
    """Draw each strategy as a layered precedence diagram (like the paper's Figure 2)."""
    from opportune.formats.draw import DotMissing, render, to_dot

    plan = load_or_exit(plan_file)
    fmt = (fmt or (output.suffix.lstrip(".") if output else "dot")).lower()
    if fmt not in {"svg", "png", "pdf", "dot"}:
        fail(f"unknown format '{fmt}': use svg, png, pdf or dot", 2)
    if fmt == "dot":
        source = to_dot(plan)
        if output:
            output.write_text(source)
            out.print(f"wrote {output}")
        else:
            sys.stdout.write(source)
        return
    if output is None:
        fail(f"give an output file with -o FILE.{fmt}", 2)
    try:
        render(plan, output, fmt)
    except DotMissing as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"cannot write {output}: {exc.strerror or exc}")
    out.print(f"wrote {output}")


# ---------------------------------------------------------------- replay


@app.command()
def replay(
    plan_file: Path = PLAN_ARG,
    looks_file: Path = typer.Argument(..., help="Looks file: one look per line ('-' for none), or JSON list of lists"),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable output"),
    explain: bool = typer.Option(False, "--explain", help="Print the reasons of every decision"),
    buffer_capacity: Optional[int] = typer.Option(None, "--buffer-capacity", min=0,
                                                  help="Buffer locations (default: unlimited)"),
):
    """Run the opportunistic policy over a file of looks and print the trace like the paper's Table 1."""
    from opportune.formats.looks import LooksError, read_looks
    from opportune.sequencer import Sequencer, SequencerError

    plan = load_or_exit(plan_file, json_errors=as_json)
    try:
        looks = read_looks(looks_file)
    except LooksError as exc:
        fail(str(exc.problem))
    seq = Sequencer(plan, buffer_capacity=buffer_capacity)
    for i, look in enumerate(looks, start=1):
        try:
            seq.step(look)
        except SequencerError as exc:
            fail(f"{looks_file}: look {i} ({' '.join(look) or '-'}): {exc}")
    if seq.state.is_complete and not seq.finished:
        seq.step(())
    rows = seq.trace
    if as_json:
        doc = [row.to_dict() | ({"reasons": row.decision.to_dict()} if explain else {}) for row in rows]
        for d in doc:
            d.pop("outcome", None)
        print(json.dumps(doc, indent=2))
        return
    table = Table(title=f"{plan.name}: opportunistic schedule")
    if explain:
        table.add_column("#", justify="right")
    for col in ("Visible", "Buffered", "Installed", "Action"):
        table.add_column(col, overflow="fold")
    for i, row in enumerate(rows, start=1):
        action = "" if row.action.kind == "done" else str(row.action)
        cells = [",".join(row.visible), ",".join(row.buffered), ",".join(row.installed), action]
        table.add_row(*([str(i)] if explain else []), *cells)
    out.print(table)
    if explain:
        for i, row in enumerate(rows, start=1):
            out.print(f"{i:>2}. " + _escape(row.decision.explain()).replace("\n", "\n   "), crop=False)
    if seq.state.is_complete:
        out.print(f"complete: {','.join(seq.state.installed)}")
    else:
        left = ", ".join(f"{p}×{n}" if n > 1 else p for p, n in seq.state.schedule.remaining.items())
        out.print(f"not complete after {len(looks)} looks; still to install: {left}")


@app.command()
def schema():
    """Print the JSON Schema of plan files."""
    from opportune.formats.validate import plan_schema

    print(json.dumps(plan_schema(), indent=2))


def main() -> None:  # console script entry point
    app()


if __name__ == "__main__":
    main()
