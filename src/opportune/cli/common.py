"""What every command of the command line shares: its consoles, its errors, its ``--json`` and its plan argument.

Every command loads the plan once through :mod:`opportune.formats` (:func:`load_or_exit`) and reports a
mistake through :func:`fail` or :func:`fail_problem`: a message that says where and what to do, on standard
error (or as ``{"error": {...}}`` on standard output under ``--json``), and a non-zero exit, never a
traceback.  Every text printed goes through :func:`printable` first: control characters are written as
escapes, never sent raw.

Imports: typer only; rich and the plan loader when a command first prints or reads a plan.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from opportune import cli_count

if TYPE_CHECKING:
    from rich.console import Console

    from opportune.formats import CheckResult
    from opportune.planning.plan import Plan

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


def out() -> Console:
    """The console of standard output."""
    return _console(stderr=False)


def err() -> Console:
    """The console of standard error."""
    return _console(stderr=True)


def progress_bar():
    """A study's progress bar (trials done / all, and the time left) on standard error: shown on a terminal
    only, and gone when the study ends."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeRemainingColumn(), console=err(), disable=not err().is_terminal, transient=True)


def complete_plan(incomplete: str) -> list[str]:
    """Shell completion of a plan argument: the shipped plans by name (``salbp:``, ``example:``); nothing
    otherwise, so that the shell completes file names (the scripts fall back to them)."""
    from opportune.datasets import EXAMPLE_PREFIX, PREFIX, examples, salbp_names

    if ":" in incomplete or PREFIX.startswith(incomplete) or EXAMPLE_PREFIX.startswith(incomplete):
        names = [PREFIX + n for n in salbp_names()] + [EXAMPLE_PREFIX + n for n, _, _ in examples()]
        return [n for n in names if n.startswith(incomplete)] if incomplete else []
    return []


PLAN_ARG = typer.Argument(..., help="Plan file: .yaml, .json, SALBP .IN2 or .alb; - for standard input; salbp:NAME, example:NAME "
                                     "(shipped: see `opportune examples`)", show_default=False,
                          autocompletion=complete_plan)


# Set by a command's --json (eagerly, before its other parameters): every error it reports is JSON too.
_json_errors = False


def new_command() -> None:
    """Forget the last command's ``--json`` (the tests run many commands in one process; a command's
    ``--json`` sets it again)."""
    global _json_errors
    _json_errors = False


def _json_mode(value: bool) -> bool:
    global _json_errors
    _json_errors = _json_errors or bool(value)
    return value


def json_option(help: str = "Machine-readable output (errors too: {\"error\": {...}} on standard output)"):
    """The ``--json`` option of a command: its output and its errors as JSON."""
    return typer.Option(False, "--json", help=help, callback=_json_mode, is_eager=True)


def print_error(error: dict, code: int) -> None:
    """Print an error as JSON on standard output: ``{"error": {..., "exit_code": code}}``."""
    print(json.dumps({"error": {**error, "exit_code": code}}, indent=2))


def fail(message: str, code: int = 1, *, as_json: bool | None = None) -> None:
    """Print ``error: message`` (the one prefix; the message is text, never markup) and exit; under
    ``--json``, ``{"error": {"message": ...}}`` on standard output instead, for a caller reading JSON."""
    if _json_errors if as_json is None else as_json:
        print_error({"message": message}, code)
    else:
        err().print(f"[bold red]error:[/] {escape(message)}", markup=True)
    raise typer.Exit(code)


def fail_problem(problem) -> None:
    """Print one :class:`~opportune.formats.problems.Problem` as ``check`` does (``where: error: ...``) and exit 1."""
    from opportune.formats.loader import CheckResult

    if _json_errors:
        print_error({"message": problem.message, **problem.to_dict()}, 1)
    else:
        print_problems(CheckResult(None, [problem]), err())
    raise typer.Exit(1)


def print_problems(result: CheckResult, console: Console) -> None:
    """Print a file's problems as ``check`` does: ``where: severity: message — hint``."""
    for p in result.problems:
        colour = "red" if p.severity == "error" else "yellow"
        where = f"{p.where}: " if p.where else ""
        hint = f" [dim]— {escape(p.hint)}[/]" if p.hint else ""
        console.print(f"{escape(where)}[{colour}]{p.severity}[/]: {escape(p.message)}{hint}")


def escape(text: str) -> str:
    """Text for rich: markup escaped, and characters that cannot be written as UTF-8 (the lone
    surrogates that stand for undecodable bytes in file names and arguments) written as escapes."""
    from rich.markup import escape as markup_escaped

    return markup_escaped(text.encode("utf-8", "backslashreplace").decode("utf-8"))


def policy_names(names) -> list[str]:
    """Policy names with each former one (``opportunistic``) replaced by its name now, each name once; the
    former names get one note on standard error (the command line's deprecation notice)."""
    from opportune.policies.named import current_names, deprecation_note

    now, former = current_names(list(names), warn=False)
    if former:
        err().print("note: " + escape("; ".join(deprecation_note(n) for n in former)))
    return list(now)


def json_invalid_plan(path: Path, result, json_errors: bool) -> bool:
    """Under ``--json``, print a plan file's errors as one JSON error and answer True; else False."""
    if json_errors or _json_errors:
        print_error({"message": f"{path}: not a valid plan ({len(result.errors)} error(s))", "file": str(path),
                     "problems": [p.to_dict() for p in result.problems]}, 1)
        return True
    return False


def command_name() -> str:
    """The command under way (``opportune graph``: "graph"), for a message."""
    try:        # typer carries its own copy of click (newer typers), whose context is the one under way
        from typer._click.globals import get_current_context
    except ImportError:
        from click import get_current_context
    ctx = get_current_context(silent=True)
    return ctx.info_name if ctx is not None else "this command"


def load_or_exit(path: Path, *, json_errors: bool = False, ways: bool = False) -> Plan:
    """Load a plan, or print every error and exit 1 (``ways``: the command takes plans written as ways)."""
    from opportune.formats.loader import CheckResult, read_plan

    result = read_plan(path)
    if result.ok and result.plan.is_ways and not ways:
        from opportune.formats.ways import not_for_ways

        fail(not_for_ways(command_name()), as_json=json_errors or None)
    if not result.ok:
        if not json_invalid_plan(path, result, json_errors):
            print_problems(CheckResult(None, result.errors), err())
            # `check` says more only when there are warnings too (it lists the same errors, and nothing
            # more for a file it cannot read): the pointer to it is given only then
            warnings = len(result.problems) - len(result.errors)
            if warnings:
                err().print(escape(f"{path}: {len(result.errors)} error(s); `opportune check {path}` lists its "
                                   f"{warnings} warning(s) too"))
            elif len(result.errors) > 1:
                err().print(escape(f"{path}: {len(result.errors)} errors"))
        raise typer.Exit(1)
    return result.plan


def write_text(output: Path, text: str) -> None:
    """Write a command's text file, or exit 1 saying why it cannot be written."""
    try:
        output.write_text(text, encoding="utf-8")
    except OSError as exc:
        fail(f"cannot write {output}: {exc.strerror or exc}")


def wrote(as_json: bool, doc: dict, output: Path) -> None:
    """Say what a command wrote: ``{..., "wrote": output}`` under ``--json``, else ``wrote output``."""
    if as_json:
        print(json.dumps({**doc, "wrote": str(output)}, indent=2))
    else:
        out().print(f"wrote {escape(str(output))}")
