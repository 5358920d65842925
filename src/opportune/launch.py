"""The ``opportune`` command's entry point.

``opportune count`` on a well-formed command line runs without typer and rich
(:func:`opportune.cli_count.quick`: 0.1 s of imports less, on a count that takes microseconds);
everything else, and any command line the quick path does not take, goes to the typer
application (:func:`opportune.cli.main`).
"""

from __future__ import annotations

import os
import sys


def main() -> None:
    if sys.argv[1:2] == ["count"] and "_OPPORTUNE_COMPLETE" not in os.environ:
        from opportune.cli_count import quick

        if quick(sys.argv[2:]):
            return
    from opportune.cli import main as typer_main

    typer_main()


if __name__ == "__main__":
    main()
