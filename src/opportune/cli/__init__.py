"""The ``opportune`` command line: the typer application and its commands, registered by group.

Each group of commands has its module; this one makes the application and registers them, in the order
``opportune --help`` lists them:

* :mod:`~opportune.cli.plans` — ``check``, ``count``, ``graph``, ``replay``, ``examples``, ``convert``, ``schema``;
* :mod:`~opportune.cli.simulate` — ``simulate`` (``--from``, ``--bound``; ``--products`` in
  :mod:`~opportune.cli.products`);
* :mod:`~opportune.cli.evaluate` — ``evaluate``;
* :mod:`~opportune.cli.service` — ``serve``, ``token create|list|revoke``, ``opcua cert``;
* :mod:`~opportune.cli.derive` — ``relax``, ``learn``, ``derive`` (where plans come from);
* :mod:`~opportune.cli.shell` — ``completion``.

What every command shares (its consoles, its errors, ``--json``, the plan argument) is in
:mod:`~opportune.cli.common`.  Every command loads the plan once through :mod:`opportune.formats` and asks
the room that does the work; user mistakes (a bad file, an unknown part, an inadmissible prefix) print a
message that says where and what to do, and exit non-zero, never with a traceback.

``opportune count`` on a well-formed command line never comes here: :mod:`opportune.launch` runs it through
:mod:`opportune.cli_count`, without typer and rich.
"""

from __future__ import annotations

import sys

import typer
from typer.core import TyperGroup

from opportune.cli import common, derive, evaluate, plans, service, shell, simulate
from opportune.cli.common import PLAN_ARG, fail, fail_problem, json_option, load_or_exit, printable
from opportune.cli.shell import COMPLETE_VAR

__all__ = ["COMPLETE_VAR", "PLAN_ARG", "app", "fail", "fail_problem", "json_option", "load_or_exit", "main",
           "printable"]

# Start-up: the command line imports only typer.  rich, the plan loader, the engine and every command's own
# machinery load when a command needs them, so `opportune count --help` never pays for them
# (tests/test_cli.py checks that the heavy packages stay out; benchmarks/bench_startup.py times it).


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


def __getattr__(name: str):  # ``cli.out`` and ``cli.err``, as before, without making them at import
    if name in ("out", "err"):
        return getattr(common, name)()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _version(value: bool) -> None:
    if value:
        from opportune import __version__

        print(f"opportune {__version__}")
        raise typer.Exit()


@app.callback()
def _options(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                          help="Print the version and exit")) -> None:
    """Least-commitment planning, scheduling and opportunistic execution (Fox & Kempf)."""
    common.new_command()


# The commands, in the order `opportune --help` lists them.
app.command()(plans.check)
app.command(help=plans.COUNT_HELP)(plans.count)
app.command()(plans.graph)
app.command()(plans.replay)
app.command()(simulate.simulate)
app.command()(evaluate.evaluate)
app.command()(plans.examples)
app.command()(plans.convert)
app.command()(plans.schema)
service.register(app)
app.command()(derive.relax)
app.command()(derive.learn)
app.command()(derive.derive)
app.command()(shell.completion)


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
        common.print_error({"message": exc.format_message()}, exc.exit_code)
        raise SystemExit(exc.exit_code) from None
    raise SystemExit(code if isinstance(code, int) else 0)
