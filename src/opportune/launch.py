"""The ``opportune`` command's entry point.

``opportune count`` on a well-formed command line runs without typer and rich
(:func:`opportune.cli_count.quick`: 0.1 s of imports less, on a count that takes microseconds);
everything else, and any command line the quick path does not take, goes to the typer
application (:func:`opportune.cli.main`).
"""

from __future__ import annotations

import os
import sys


def defer(name: str) -> None:
    """Import the standard module ``name`` at the first use of one of its names instead of at its
    import: until then ``sys.modules[name]`` is a stand-in whose missing names load the module
    (and then come from it); nothing if ``name`` is already loaded.

    ``dataclasses`` imports ``inspect`` (with ``ast``, ``dis`` and ``tokenize``: 5 ms, a twentieth
    of a small count's start-up) for one use, the signature of a class without a docstring, which
    no class on the count's path is.  Only this entry point defers it: a process that imports
    opportune as a library keeps its modules as Python loads them.  (``importlib.util.LazyLoader``
    cannot do this before Python 3.12: ``import inspect`` reads the module's ``__spec__``, which
    loads it.)
    """
    if name in sys.modules:
        return
    import importlib.util
    import types

    spec = importlib.util.find_spec(name)
    if spec is None:
        return

    class Deferred(types.ModuleType):
        def __getattr__(self, attr: str):
            if sys.modules.get(name) is self:
                del sys.modules[name]
            module = importlib.import_module(name)
            return getattr(module, attr)

    stand_in = Deferred(name)
    stand_in.__spec__ = spec
    sys.modules[name] = stand_in


def main() -> None:
    if sys.argv[1:2] == ["count"] and "_OPPORTUNE_COMPLETE" not in os.environ:
        defer("inspect")
        from opportune import cli_count

        cli_count.held = []
        try:
            if cli_count.quick(sys.argv[2:]):
                end(0, cli_count.held)
                return
            from opportune.cli import main as typer_main

            typer_main()
        except SystemExit as exc:
            end(exc.code, cli_count.held)
            raise
        return
    from opportune.cli import main as typer_main

    typer_main()


def end(code, held: list) -> None:
    """End the process now, without freeing what the count built, once its answer is out: freeing a long
    count's memos (millions of small allocations) took up to a second past ``--time-limit``.  Only when a
    count built something; the exit handlers still run (``atexit``: a coverage tool's, a test's), only the
    freeing of the interpreter's objects is skipped.  If the answer cannot be written (a closed pipe), or
    the exit status is not a number, the usual exit."""
    if not any(x is not None for x in held):
        return
    if code is None:
        code = 0
    elif not isinstance(code, int):     # SystemExit("message"): as Python prints it
        return
    import atexit

    try:
        sys.stdout.flush()
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        return
    os._exit(code)
