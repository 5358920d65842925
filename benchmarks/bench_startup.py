"""Start-up time of the command line: each command imports only what it needs.

Targets on an idle machine: ``opportune count --help`` in at most 0.06 s wall, and counting a
6-element order in at most 0.12 s (Python's own start is about 0.02 s here).  ``count`` on a
well-formed command line runs without typer and rich (``opportune.launch``).  Runs each command
as a fresh subprocess with this interpreter (the console script ``opportune`` beside it when there
is one, as a user runs it), ``--runs`` times after ``--warmup`` untimed runs, and prints the best
and the median wall time, plus the heavy packages each command loaded (``sys.modules`` at exit,
from one more run).  Bytecode is written and used, as in an installed package
(``PYTHONDONTWRITEBYTECODE`` is cleared for the runs).  An editable install (``pip install -e``)
adds its import hook to every start (about 10 ms): the ``python -c pass`` row shows the
interpreter's own start with it.

    python benchmarks/bench_startup.py [--runs 10] [--warmup 2]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
GEARBOX = "examples/gearbox.yaml"
SIX = "six.yaml"    # written into a temporary folder: a 6-element order (two chains and two free parts)
SIX_TEXT = "name: six\nparts: [a, b, c, d, e, f]\nrequires:\n  c: [a]\n  d: [b]\n"
COMMANDS = (
    ("--help",),
    ("count", "--help"),
    ("count", SIX),
    ("count", GEARBOX),
    ("check", GEARBOX),
    ("count", "salbp:KILBRID"),
)
TARGETS = {("count", "--help"): 0.06, ("count", SIX): 0.12}
# Packages no plain command should pay for (and the big pieces of typer's own start-up).
HEAVY = ("matplotlib", "numpy", "fastapi", "sqlalchemy", "uvicorn", "dask", "distributed", "graphviz",
         "jsonschema", "yaml", "pydantic", "typer", "rich", "rich.markdown", "opportune.engine.schedule")


def command_prefix() -> list[str]:
    """How to start ``opportune`` with this interpreter: the console script if installed beside it."""
    script = Path(sys.executable).with_name("opportune")
    if script.is_file():
        return [sys.executable, str(script)]
    return [sys.executable, "-c", "import sys; from opportune.launch import main; sys.argv[0] = 'opportune'; main()"]


def run_once(argv: list[str], env: dict) -> tuple[float, float, int]:
    """Wall seconds, CPU seconds (user + system) and exit code of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(argv, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc.returncode


def heavy_loaded(cmd: tuple[str, ...], env: dict) -> list[str]:
    """The modules of ``HEAVY`` in ``sys.modules`` when ``opportune CMD...`` exits (one more run, in
    an interpreter that runs the command line's entry point and then lists its modules)."""
    code = ("import atexit, sys\n"
            "atexit.register(lambda: sys.__stderr__.write('\\nMODULES ' + ' '.join(sys.modules) + '\\n'))\n"
            f"sys.argv = ['opportune', *{list(cmd)!r}]\n"
            "from opportune.launch import main\nmain()\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    line = next((ln for ln in reversed(proc.stderr.splitlines()) if ln.startswith("MODULES ")), "MODULES ?")
    names = set(line.split()[1:])
    return [h for h in HEAVY if h in names]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10, help="timed runs per command")
    ap.add_argument("--warmup", type=int, default=2, help="untimed runs first (fills the OS file cache)")
    args = ap.parse_args()

    # A fixed terminal width so help renders the same way every run; no colour codes.
    env = dict(os.environ, COLUMNS="100", NO_COLOR="1", TERM="dumb")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    tmp = tempfile.mkdtemp(prefix="opportune-startup-")
    six = Path(tmp) / SIX
    six.write_text(SIX_TEXT)
    prefix = command_prefix()
    console = Console() if sys.stdout.isatty() else Console(width=150)
    load = os.getloadavg()[0]
    table = Table(title=f"opportune start-up: seconds over {args.runs} runs "
                        f"({'console script' if len(prefix) == 2 else 'python -c'}, python {sys.version.split()[0]}, "
                        f"{os.cpu_count()} cores, load average {load:.1f})",
                  caption="CPU = user + system time of the process; on a busy machine wall time is longer")
    for col, justify in (("command", "left"), ("best wall", "right"), ("median wall", "right"),
                         ("median CPU", "right"), ("target (median wall)", "right"), ("heavy modules loaded", "left")):
        table.add_column(col, justify=justify)
    python = min(run_once([sys.executable, "-c", "pass"], env)[0] for _ in range(args.runs))
    for cmd in COMMANDS:
        argv = [*prefix, *(str(six) if c == SIX else c for c in cmd)]
        for _ in range(args.warmup):
            run_once(argv, env)
        runs = [run_once(argv, env) for _ in range(args.runs)]
        walls, cpus, codes = [r[0] for r in runs], [r[1] for r in runs], {r[2] for r in runs}
        target = TARGETS.get(cmd)
        best, median = min(walls), statistics.median(walls)
        ok = "" if target is None else (f"[green]≤ {target}[/]" if median <= target else f"[red]≤ {target} (missed)[/]")
        label = "opportune " + " ".join(cmd) + ("" if codes == {0} else f"  [red](exit {sorted(codes)})[/]")
        table.add_row(label, f"{best:.3f}", f"{median:.3f}", f"{statistics.median(cpus):.3f}", ok,
                      ", ".join(heavy_loaded(tuple(argv[len(prefix):]), env)) or "-")
    table.add_row("[dim]python -c pass[/]", f"[dim]{python:.3f}[/]", "", "", "", "")
    console.print(table)


if __name__ == "__main__":
    main()
