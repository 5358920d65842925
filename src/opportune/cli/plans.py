"""Commands on a plan itself: ``check``, ``count``, ``graph``, ``replay``, ``convert``, ``schema`` and ``examples``.

Each reads the plan through :func:`~opportune.cli.common.load_or_exit` and asks the room that does the
work (:mod:`opportune.formats` for reading, checking, drawing and writing; the engine through
:mod:`opportune.cli_count` for counting; the sequencer for a replay); what is here is option plumbing
and printing.

Imports: typer only; each command loads its own machinery when it runs.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

from opportune import cli_count
from opportune.cli.common import (PLAN_ARG, complete_plan, err, escape, fail, fail_problem, json_option, load_or_exit,
                                  out, policy_names, print_error, print_problems, write_text, wrote)
from opportune.limits import MAX_BUFFER


# ---------------------------------------------------------------- check


def check(plan_files: list[Path] = typer.Argument(..., help="Plan files (any format `count` reads; - for standard "
                                                              "input; salbp:NAME, example:NAME)", show_default=False,
                                                  autocompletion=complete_plan),
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
            out().print()
        _print_check(plan_file, result)
    if as_json:
        print(json.dumps(docs[0] if len(docs) == 1 else {"valid": ok, "files": docs}, indent=2))
    elif len(plan_files) > 1:
        out().print(f"\n{len(plan_files)} files: " + ("all valid" if ok else "some invalid (above)"))
    raise typer.Exit(0 if ok else 1)


def _print_check(plan_file: Path, result) -> None:
    """``check``'s report of one file: its problems, or its summary (and warnings)."""
    from opportune.formats.summary import summarize, ways_line

    if not result.ok:
        print_problems(result, out())
        n = len(result.errors)
        out().print(f"[red]{escape(str(plan_file))}: invalid[/] — {n} error{'s' if n != 1 else ''}"
                    + (f", {len(result.warnings)} warning(s)" if result.warnings else ""))
        return
    s = summarize(result.plan)
    out().print(f"[bold]{escape(s['plan'])}[/] ({escape(str(plan_file))}): [green]valid[/]")
    units = f" ({s['units']} units)" if s["units"] != s["parts"] else ""
    if "ways" in s:      # a plan written as ways (opportune.formats.ways)
        out().print(f"  parts: {s['parts']}; written as ways: {escape(ways_line(s['ways']))}")
    else:
        out().print(f"  parts: {s['parts']}{units}; strategies: {len(s['strategies'])}")
    for st in s["strategies"]:
        out().print(f"  strategy '{escape(st['name'])}': {st['declared']} constraints declared, "
                    f"{len(st['minimal'])} minimal, {st['implied']} implied in all (transitive closure)")
        shown = st["minimal"][:40]
        text = ", ".join(f"{a} -> {b}" for a, b in shown) or "(none: any order)"
        if len(st["minimal"]) > len(shown):
            text += f", … ({len(st['minimal']) - len(shown)} more; --json lists all)"
        out().print(f"    minimal constraints: {escape(text)}", crop=False)
    if result.warnings:
        out().print(f"  {len(result.warnings)} warning(s):")
        print_problems(result, out())


# ---------------------------------------------------------------- count


def _count_option(name: str, **extra):
    """A ``count`` option from :data:`opportune.cli_count.OPTIONS` (the quick path reads the same table)."""
    flag, kind, default, text = cli_count.OPTIONS[name]
    if kind is None:
        return json_option(text)
    return typer.Option(default, flag, help=text, **extra)


#: ``count``'s help: the quick path (:func:`opportune.cli_count.help_text`) prints the same.
COUNT_HELP = f"{cli_count.SUMMARY}\n\n{cli_count.DESCRIPTION}"


def count(
    plan_file: Path = typer.Argument(..., help=cli_count.PLAN_HELP, show_default=False, autocompletion=complete_plan),
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
            out().print(line, markup=False, emoji=False)

    cli_count.run(plan_file, after, as_json, time_limit, max_memo, threads,
                  load=lambda path: load_or_exit(path, json_errors=as_json, ways=True), fail=fail, write=write)


# ---------------------------------------------------------------- graph


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
    wrote(as_json, {"plan": plan.name, "format": fmt}, output)


# ---------------------------------------------------------------- replay


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
    from opportune.formats.looks import LooksError, read_looks
    from opportune.sequencer import Sequencer, SequencerError

    plan = load_or_exit(plan_file, json_errors=as_json, ways=True)
    try:
        looks = read_looks(looks_file)
    except LooksError as exc:
        fail_problem(exc.problem)
    from opportune.policies.named import UnknownPolicy, make_policy

    policy = policy_names([policy])[0]
    from opportune.formats.ways import WAYS_POLICIES, not_for_ways

    if plan.is_ways and policy not in WAYS_POLICIES:
        fail(not_for_ways(f"the policy '{policy}'"), 2)
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
            print_error({"message": stopped, "trace": doc}, 1)
            raise typer.Exit(1)
        print(json.dumps(doc, indent=2))
        return
    _print_trace(f"{plan.name}: " + ("the paper's rule" if chosen.name == "paper" else f"{chosen.name} schedule"),
                 rows, explain, stopped)
    if stopped is not None:
        fail(stopped)
    if seq.state.is_complete:
        out().print(f"complete: {','.join(seq.state.installed)}")
    else:
        left = ", ".join(f"{p}×{n}" if n > 1 else p for p, n in seq.state.schedule.remaining.items())
        out().print(f"not complete after {len(looks)} looks; still to install: {left}")


def _print_trace(title: str, rows, explain: bool, stopped: Optional[str]) -> None:
    """``replay``'s trace as the paper's Table 1 (numbered, and each decision's reasons after it, with
    ``--explain``)."""
    from rich.table import Table

    from opportune.policies.printable import printable_decision

    table = Table(title=title + (f" (stopped after {len(rows)} looks)" if stopped else ""))
    if explain:
        table.add_column("#", justify="right")
    for col in ("Visible", "Buffered", "Installed", "Action"):
        table.add_column(col, overflow="fold")
    for i, row in enumerate(rows, start=1):
        action = "" if row.action.kind == "done" else str(row.action)
        cells = [",".join(row.visible), ",".join(row.buffered), ",".join(row.installed), action]
        table.add_row(*([str(i)] if explain else []), *cells)
    out().print(table)
    if explain:
        for i, row in enumerate(rows, start=1):
            out().print(f"{i:>2}. " + escape(printable_decision(row.decision).explain()).replace("\n", "\n   "),
                        crop=False)


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
        out().print(f"{escape(r['name']):<{width}}  {r['kind']:<9}  {escape(r['about'])}")
    out().print("e.g. opportune replay example:gearbox example:gearbox-table1; opportune count salbp:KILBRID")


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
        err().print(escape(f"note: an .alb file numbers its tasks: the parts are 1 to {len(plan.parts)} in their "
                             f"order in the plan ({shown}{more}); the plan's name and the parts' names are not "
                             "kept"))
    if str(output) == "-":
        if as_json:
            print(json.dumps({"plan": plan.name, "format": fmt, "text": text}, indent=2))
        else:
            sys.stdout.write(text)
        return
    write_text(output, text)
    wrote(as_json, {"plan": plan.name, "format": fmt}, output)


def schema():
    """Print the JSON Schema of plan files."""
    from opportune.formats.validate import plan_schema

    print(json.dumps(plan_schema(), indent=2))
