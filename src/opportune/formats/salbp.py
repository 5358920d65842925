"""Scholl's SALBP precedence graphs (``.IN2``) read as single-strategy plans.

Format: the number of tasks *n*; *n* task durations; precedence pairs ``i,j``
(task *i* before task *j*, 1-based), one per line; ``-1,-1`` ends the data.
Real files are messy: CRLF line ends, blank lines, Latin-1 free text after the
end marker.  Parts are named by task number; durations become per-part
``install`` costs.

A file without its end marker is refused as truncated (a file cut short
would otherwise be a valid graph with fewer constraints, and every count of
it wrong), as ``.alb`` files without ``<end>`` are.  A repeated pair is one
warning, however often it repeats: reading is O(size of the file).  At most
:data:`~opportune.formats.graphs.MAX_TASKS` tasks and
:data:`~opportune.formats.graphs.MAX_PAIRS` precedence lines are read, in a file
of at most :data:`~opportune.formats.graphs.MAX_LINES` lines (counted on the
bytes before any line is built; a long line costs nothing here: every value is
matched by a pattern of bounded length).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from opportune.formats.graphs import (DECIMAL, MAX_PAIRS, MAX_TASKS, PAIR, Findings, GraphFormatError, check_graph,
                                      file_bytes, in_file_order, last_nonblank, show, text_lines, to_int,
                                      too_many_lines)
from opportune.formats.documents import CheckResult
from opportune.formats.problems import Problem


@dataclass(frozen=True)
class In2:
    """The raw content of an ``.IN2`` file: ``pairs`` are distinct 1-based ``(before, after)`` task numbers."""

    n: int
    durations: tuple[int | float, ...]
    pairs: tuple[tuple[int, int], ...]
    trailer: str = ""
    lines: dict = field(default_factory=dict, compare=False, repr=False)  # (before, after) -> line number


class In2Error(GraphFormatError):
    """An ``.IN2`` file that cannot be read; ``problems`` lists every problem."""


def parse_in2(raw: bytes, file: str | None = None) -> tuple[In2 | None, list[Problem]]:
    """Parse ``.IN2`` bytes; return the content (``None`` on error) and every problem found.

    Warnings (repeated pairs) come with a usable content.  O(size of the file).
    """
    out = Findings(file, code="in2")
    refused = too_many_lines(raw, file)  # before the lines are built
    if refused:
        return None, refused
    lines = text_lines(raw)  # ASCII up to the end marker; comments after it are Latin-1

    def done():
        return None, in_file_order(out.finish())

    # Significant lines with their 1-based numbers, until the end marker.
    it = ((no, s) for no, s in ((i + 1, ln.strip()) for i, ln in enumerate(lines)) if s)
    first_row = next(it, None)
    if first_row is None:
        out.add("the file is empty", "an .IN2 file starts with the number of tasks", 1)
        return done()
    no, first = first_row
    n = to_int(first)
    if n is None or n < 1:
        out.add(f"first line should be the number of tasks, found {show(first)}",
                "an .IN2 file starts with a positive integer", no)
        return done()
    if n > MAX_TASKS:
        out.add(f"{n:,} tasks is more than this reader accepts ({MAX_TASKS:,})", "split the graph into smaller ones",
                no, code="limit")
        return done()
    durations: list[int | float] = []
    for _ in range(n):
        row = next(it, None)
        if row is None:
            out.add(f"the file ends after {len(durations)} of {n} task durations",
                    "give one duration per task (a file cut short lacks the last ones)", last_nonblank(lines))
            return done()
        no, s = row
        d = to_int(s)
        if d is None and DECIMAL.fullmatch(s):
            d = float(s.replace(",", "."))
        if d is None or d < 0:
            out.add(f"task {len(durations) + 1}: duration {show(s)} is not a number ≥ 0", "one duration per line", no)
            return done()
        durations.append(d)
    first_line: dict[tuple[int, int], int] = {}
    repeats: dict[tuple[int, int], list[int]] = {}  # pair -> [count, line of the first repeat]
    end_line = None
    for k, (no, s) in enumerate(it):
        if k == MAX_PAIRS and not ((m := PAIR.fullmatch(s)) and (int(m[1]), int(m[2])) == (-1, -1)):
            # (the end marker right after MAX_PAIRS pairs is no pair)
            out.add(f"more than {MAX_PAIRS:,} precedence lines", "split the graph into smaller ones", no, code="limit")
            return done()
        match = PAIR.fullmatch(s)
        if match is None:
            out.add(f"precedence line {show(s)} is not 'i,j'",
                    "write one pair of task numbers per line, e.g. 3,7; end with -1,-1", no)
            continue
        a, b = int(match[1]), int(match[2])
        if (a, b) == (-1, -1):
            end_line = no
            break
        if not (1 <= a <= n and 1 <= b <= n):
            bad = a if not 1 <= a <= n else b
            out.add(f"precedence {a},{b} names task {bad}, but tasks are numbered 1..{n}", "fix the task number", no,
                    parts=(str(a), str(b)))
            continue
        if a == b:
            out.add(f"task {a} requires itself", "remove this line", no, parts=(str(a),))
            continue
        pair = (a, b)
        if pair not in first_line:
            first_line[pair] = no
        elif pair in repeats:
            repeats[pair][0] += 1
        else:
            repeats[pair] = [1, no]
    if end_line is None:
        out.add("the file ends without its end marker `-1,-1`: it is probably truncated, and a graph cut short "
                "has fewer constraints (every count of it would be wrong)",
                "check that the whole file was copied; an .IN2 file ends its precedence pairs with a line -1,-1",
                last_nonblank(lines), code="truncated")
    for (a, b), (count, line) in repeats.items():
        times = "once" if count == 1 else f"{count:,} times"
        out.add(f"precedence {a},{b} is repeated {times} (first at line {first_line[(a, b)]}); the repeats are ignored",
                "remove the repeated lines", line, code="repeated", severity="warning", parts=(str(a), str(b)))
    if out.has_errors:
        return done()
    trailer = "\n".join(lines[end_line:]).strip()
    content = In2(n=n, durations=tuple(durations), pairs=tuple(first_line), trailer=trailer, lines=first_line)
    return content, in_file_order(out.finish())


def read_in2(path: str | Path) -> In2:
    """Read an ``.IN2`` file; raise :class:`In2Error` with every problem.

    >>> g = read_in2(salbp_path("MERTENS"))  # doctest: +SKIP
    >>> g.n, len(g.pairs)                                  # doctest: +SKIP
    (7, 6)
    """
    content, problems = parse_in2(file_bytes(path, In2Error), file=str(path))
    if content is None:
        raise In2Error(problems)
    return content


def check_in2_bytes(raw: bytes, *, file: str | None = None) -> CheckResult:
    """Read ``.IN2`` bytes as a single-strategy plan (parts '1'..'n'), checked like any plan."""
    content, problems = parse_in2(raw, file)
    if content is None:
        return CheckResult(None, problems)
    checked = check_graph(content.durations, content.pairs, content.lines, file=file,
                          source="SALBP precedence graph", default_name="salbp")
    return CheckResult(checked.plan, problems + checked.problems)
