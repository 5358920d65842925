"""``opportune count`` without typer or rich: the command's options, its help and its work, in one place.

Counting a small plan takes microseconds; a command line that loads typer and rich first (0.1 s
of imports) makes every count pay for them.  :func:`opportune.launch.main` hands a well-formed
``count`` command line to :func:`quick` before typer is imported; anything else (an unknown or
malformed option, a missing plan, any error while reading the plan or checking ``--after``) goes
on to the typer command, which runs the same :func:`run` and says what is wrong.  The typer
command takes its option names, defaults and help texts from :data:`OPTIONS`, so the two cannot
drift apart (a test compares their help).

Imports: the plan loader and the engine, when a plan is counted; nothing else.
"""

from __future__ import annotations

import math
import sys

SUMMARY = ("Count the admissible sequences of a plan (exact integer; an estimate, marked so, only over "
           "budget).")
DESCRIPTION = ("Answers within --time-limit seconds plus 0.25 s (after Python's start-up), on every plan it "
               "reads: exact if the count finishes in time, else an estimate with an interval (from the runs "
               "of the estimator, within bounds the order itself gives, which always hold).")
PLAN_HELP = ("Plan file: .yaml, .json, SALBP .IN2 or .alb; - for standard input; salbp:NAME, example:NAME "
             "(shipped: see `opportune examples`)")
JSON_HELP = "Machine-readable output (errors too: {\"error\": {...}} on standard output)"
#: The options: name -> (flag, value type or None for a flag, default, help).
OPTIONS = {
    "after": ("--after", str, None, 'Parts installed first, in order: "ca ba" or "ca,ba"'),
    "as_json": ("--json", None, False, JSON_HELP),
    "time_limit": ("--time-limit", float, 10.0,
                   ("Seconds in all, reading the plan included; the answer comes within them plus 0.25 s: "
                    "about two thirds for the exact count (plainly and through a hub, in turns), then (only if "
                    "still needed) an estimate with an interval")),
    "max_memo": ("--max-memo", int, 0, "Memo entries for an exact count before estimating (0: as many as "
                 "a quarter of the machine's memory holds)"),
    "threads": ("--threads", int, 0, "Threads that count and draw when the count is estimated (0: one per "
                "core); the estimate is the same for any number, but for a stop on the clock"),
}
#: Threads the estimate may count and draw on, at most (``--threads``).
MAX_THREADS = 256   # as opportune.engine.relaxmc.MAX_THREADS (not imported here: the help loads no engine)
MIN_TIME_LIMIT = 0.1
#: What the counts of this process built (their engines and memos), kept here instead of freed when
#: :func:`opportune.launch.main` runs the command: freeing a long count's memos takes up to a second
#: (a hub's tail distributions are millions of small allocations), so the process writes its answer
#: and ends without freeing them.  None (a library or a test runs the command): freed as usual, after
#: the answer is written.
held: list | None = None


class Refer(Exception):
    """The quick path cannot serve this command line: the typer command will (and explain any error)."""


def parse(argv: list[str]) -> dict | None:
    """The arguments of ``count`` (``argv`` after the word ``count``) as keyword arguments of :func:`run`,
    ``{"help": True}`` for a request for help, or None when anything is unusual (typer then parses
    it and reports what is wrong).  O(len(argv))."""
    flags = {flag: name for name, (flag, *_rest) in OPTIONS.items()}
    out = {name: default for name, (_f, _t, default, _h) in OPTIONS.items()}
    plan = None
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg in ("-h", "--help"):
            return {"help": True}
        if arg.startswith("--"):
            flag, eq, value = arg.partition("=")
            name = flags.get(flag)
            if name is None:
                return None
            kind = OPTIONS[name][1]
            if kind is None:
                if eq:
                    return None
                out[name] = True
            else:
                if not eq:
                    i += 1
                    if i >= len(argv):
                        return None
                    value = argv[i]
                try:
                    out[name] = kind(value)
                except ValueError:
                    return None
        elif arg.startswith("-") and arg != "-" or plan is not None:
            return None
        else:
            plan = arg
        i += 1
    if (plan is None or not out["time_limit"] >= MIN_TIME_LIMIT or not math.isfinite(out["time_limit"])
            or not 0 <= out["threads"] <= MAX_THREADS):
        return None
    out["plan_file"] = plan
    return out


def help_text(width: int = 80) -> str:
    """The command's help, in click's plain layout (as ``opportune count --help`` prints it through typer)."""
    import textwrap

    def para(text: str, indent: str) -> str:
        return textwrap.fill(text, width, initial_indent=indent, subsequent_indent=indent)

    ranges = {"time_limit": f"x>={MIN_TIME_LIMIT}", "threads": f"0<=x<={MAX_THREADS}"}   # as the typer options say
    rows = []
    for name, (flag, kind, default, text) in OPTIONS.items():
        label = {str: "str", int: "int", float: "float"}.get(kind, "") + (" range" if name in ranges else "")
        head = flag if kind is None else f"{flag} <{label}>"
        extra = []
        if kind is not None and default is not None:
            extra.append(f"default: {default}")
        if name in ranges:
            extra.append(ranges[name])
        rows.append((head, text + (f"  [{'; '.join(extra)}]" if extra else "")))
    rows.append(("-h, --help", "Show this message and exit."))
    col = min(max(len(h) for h, _ in rows) + 4, 30)
    lines = ["Usage: opportune count [OPTIONS] {plan_file}", "", para(SUMMARY, "  "), "",
             para(DESCRIPTION, "  "), "", "Arguments:"]
    lines.append(textwrap.fill(PLAN_HELP + "  [required]", width, initial_indent="  plan_file  ",
                               subsequent_indent=" " * 13))
    lines += ["", "Options:"]
    for head, text in rows:
        first = f"  {head}".ljust(col)
        if len(first) > col:            # a long option name: its text starts on the next line
            lines.append(first)
            first = " " * col
        lines.append(textwrap.fill(text, width, initial_indent=first, subsequent_indent=" " * col))
    return "\n".join(lines) + "\n"


def run(plan_file, after: str | None, as_json: bool, time_limit: float, max_memo: int, threads: int = 0, *,
        load, fail, write) -> None:
    """Count ``plan_file`` (a path or a ``salbp:``/``example:`` name) after ``after``, within ``time_limit``
    seconds in all, reading the plan included.  ``load(path)`` gives the plan (or does not return),
    ``fail(message, as_json=...)`` reports a user's mistake (and does not return), ``write(line)``
    prints one line of the answer; ``threads``: threads that count and draw in an estimate (0: one per core).  See
    :func:`opportune.engine.schedule.Schedule.count_result`.  The engine is freed only after the answer is
    written (or never: :data:`held`)."""
    from opportune.engine.deadline import Deadline

    # one deadline for the whole command: loading the engine, reading the plan and building its orders count too
    deadline = Deadline.after(time_limit)
    if threads == 0:
        import os

        threads = min(MAX_THREADS, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    from opportune.engine import NotAdmissible, OrderEngine, Schedule
    from opportune.engine.deadline import BudgetExceeded
    from opportune.engine.schedule import decimal, interval_unbuilt

    plan = load(plan_file)
    prefix = [p for p in (after or "").replace(",", " ").split() if p]
    # The engine's time limit (a tenth) and count_result's (the rest) make the one deadline: the exact
    # count takes turns until about two thirds of it, the estimate the rest (Schedule.count_result).  Building the strategies' orders gets at most half of what is left (64 strategies over 10,000 parts
    # take seconds); past it, the interval that holds without them.
    try:
        engine = OrderEngine(plan, max_memo=max_memo, time_limit=time_limit / 10, deadline=deadline.share(0.5))
    except BudgetExceeded:
        if prefix:
            fail(f"the plan's {len(plan.strategies)} strategies could not be built within --time-limit "
                 f"{time_limit:g} s to check --after: raise --time-limit", as_json=as_json)
        engine = None
    if engine is None:
        result = interval_unbuilt(plan)
    else:
        sched = Schedule(engine)
        for i, part in enumerate(prefix):
            try:
                sched = sched.install(part)
            except NotAdmissible as exc:
                done = " ".join(prefix[:i]) or "nothing"
                fail(f"--after: {exc} (after installing {done}); the prefix is not admissible", as_json=as_json)
        result = sched.count_result(time_limit=time_limit * 9 / 10, deadline=deadline, threads=threads)
        if held is not None:
            held.append(engine)
    interval = result.interval_log10
    if as_json:
        doc = {
            "plan": plan.name,
            "parts": len(plan.parts),
            "strategies": len(plan.strategies),
            "after": prefix,
            "sequences": decimal(result.value) if result.exact else
            (sci(result.log10, 6) if math.isfinite(result.log10) else None),
            "log10": round(result.log10, 6) if math.isfinite(result.log10) else None,
            "exact": result.exact,
        }
        if not result.exact:    # null, not a non-standard Infinity, where the runs gave no bound
            doc.update(rel_error=result.rel_error if math.isfinite(result.rel_error) else None,
                       confidence=result.confidence, method=result.method)
            if interval is not None:
                doc.update(log10_low=round(interval[0], 6), log10_high=round(interval[1], 6),
                           interval_certain=not math.isfinite(result.rel_error))
        import json

        write(json.dumps(doc, indent=2))
        return
    name = plan.name
    state = f" after {' '.join(prefix)}" if prefix else ""
    if result.exact:
        noun = "admissible sequence" if result.value == 1 else "admissible sequences"
        write(f"{name}{state}: {decimal(result.value)} {noun} (log10 {result.log10:.3f})")
    elif interval is not None and not math.isnan(result.log10) and not result.rel_error < 1:
        # a wide estimate: the interval says what is known (within bounds the order itself gives)
        lo, hi = interval
        where = f"between {sci(lo, 1)} and {sci(hi, 1)} (log10 {lo:.1f} to {hi:.1f})"
        known = (f"{where} at {100 * result.confidence:.0f}% confidence ({result.method})"
                 if math.isfinite(result.rel_error) else
                 f"certainly {where}, from the order itself; no error can be stated from the samples "
                 f"({result.method})")
        write(f"{name}{state}: about {sci(result.log10, 1)} admissible sequences "
              f"(log10 {result.log10:.1f}) — ESTIMATE, only the order of magnitude is known: {known}; "
              f"the exact count exceeded the budget (a longer --time-limit narrows it)")
    elif math.isnan(result.log10):
        write(f"{name}{state}: not counted — the exact count exceeded the budget and the "
              f"estimate ({result.method}) did not finish a run within it: allow more time with --time-limit")
    elif result.rel_error < 1:
        write(f"{name}{state}: about {sci(result.log10, 4)} admissible sequences "
              f"(log10 {result.log10:.3f}) — ESTIMATE, ±{100 * result.rel_error:.2f}% at "
              f"{100 * result.confidence:.0f}% confidence ({result.method}); the exact count exceeded the budget")
    else:
        # an interval of ±100% or more bounds nothing from below: say what is known, not a percentage
        bound = (f"at most {sci(result.log10 + math.log10(1 + result.rel_error), 1)} at "
                 f"{100 * result.confidence:.0f}% confidence" if math.isfinite(result.rel_error) else
                 "its runs disagree too much to bound it")
        write(f"{name}{state}: about {sci(result.log10, 1)} admissible sequences "
              f"(log10 {result.log10:.1f}) — ESTIMATE, only the order of magnitude is known: {bound} "
              f"({result.method}); the exact count exceeded the budget (a longer --time-limit narrows it)")


def sci(log10: float, digits: int) -> str:
    """A positive number given by its log10, in scientific notation, however large (``1.2346e+403``).

    >>> import math
    >>> sci(403 + math.log10(1.2346), 4), sci(math.log10(999.99999), 4)
    ('1.2346e+403', '1.0000e+03')
    """
    if not math.isfinite(log10):
        return "nan" if math.isnan(log10) else ("0" if log10 < 0 else "inf")
    exponent = math.floor(log10)
    mantissa = 10 ** (log10 - exponent)
    if round(mantissa, digits) >= 10:       # 9.99995 rounds up to the next power of ten
        mantissa, exponent = mantissa / 10, exponent + 1
    return f"{mantissa:.{digits}f}e{exponent:+03d}"


_CONTROL = None


def printable(text: str) -> str:
    """``text`` with every control character but tab and line feed written as an escape (``\\x1b``).

    >>> printable("a\\x1b[2Jb\\tc")
    'a\\\\x1b[2Jb\\tc'
    """
    global _CONTROL
    if _CONTROL is None:
        import re

        from opportune.formats.problems import CONTROL_CHARS

        _CONTROL = re.compile(f"[{CONTROL_CHARS}]")
    return _CONTROL.sub(lambda m: ascii(m.group())[1:-1], text)


def printable_line(text: str) -> str:
    """``text`` as the terminal may see it: :func:`printable`, and undecodable bytes (the lone surrogates
    that stand for them in file names) written as escapes, as the typer command's console writes them."""
    return printable(text).encode("utf-8", "backslashreplace").decode("utf-8")


def terminal_columns() -> int:
    """The terminal's width as :func:`shutil.get_terminal_size` gives it (``COLUMNS``, else the terminal
    of standard output, else 80), without shutil's imports (a fifth of ``count --help``'s start-up)."""
    import os

    try:
        columns = int(os.environ.get("COLUMNS", "0"))
    except ValueError:
        columns = 0
    if columns <= 0:
        try:
            columns = os.get_terminal_size(sys.__stdout__.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 0
    return columns if columns > 0 else 80


def quick(argv: list[str]) -> bool:
    """Run ``opportune count ARGV...`` without typer when the command line is well formed and nothing goes
    wrong; False when the typer command must take it (from the start: nothing has been printed)."""
    args = parse(argv)
    if args is None:
        return False
    if args.get("help"):
        sys.stdout.write(help_text(min(terminal_columns(), 120)))
        return True

    def load(path):
        from opportune.formats.loader import read_plan

        if path == "-":
            raise Refer          # standard input can be read once: the typer command reads it
        result = read_plan(path)
        if not result.ok:
            raise Refer
        return result.plan

    def fail(message, *, as_json=None):
        # as the typer command's fail() prints it (counting again there would take the time limit twice)
        if as_json:
            import json

            print(json.dumps({"error": {"message": message, "exit_code": 1}}, indent=2))
        else:
            red = sys.stderr.isatty() and "NO_COLOR" not in __import__("os").environ
            sys.stderr.write(("\x1b[1;31merror:\x1b[0m " if red else "error: ") + printable_line(message) + "\n")
        raise SystemExit(1)

    lines: list[str] = []
    try:
        run(args["plan_file"], args["after"], args["as_json"], args["time_limit"], args["max_memo"], args["threads"],
            load=load, fail=fail, write=lines.append)
    except Refer:
        return False
    out = sys.stdout
    for line in lines:
        out.write((line if args["as_json"] else printable_line(line)) + "\n")
    return True
