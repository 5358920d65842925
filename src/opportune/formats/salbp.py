"""Scholl's SALBP precedence graphs (``.IN2``) read as single-strategy plans.

Format: the number of tasks *n*; *n* task durations; precedence pairs ``i,j``
(task *i* before task *j*, 1-based), one per line; ``-1,-1`` ends the data.
Real files are messy: CRLF line ends, blank lines, Latin-1 free text after the
end marker.  Parts are named by task number; durations become per-part
``install`` costs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from opportune.formats.graphs import GraphFormatError, check_graph, text_lines
from opportune.formats.loader import CheckResult
from opportune.formats.problems import Problem


@dataclass(frozen=True)
class In2:
    """The raw content of an ``.IN2`` file: ``pairs`` are 1-based ``(before, after)`` task numbers."""

    n: int
    durations: tuple[int | float, ...]
    pairs: tuple[tuple[int, int], ...]
    trailer: str = ""
    lines: dict = field(default_factory=dict, compare=False, repr=False)  # (before, after) -> line number


class In2Error(GraphFormatError):
    """An ``.IN2`` file that cannot be read; ``problems`` lists every problem."""


def parse_in2(raw: bytes, file: str | None = None) -> tuple[In2 | None, list[Problem]]:
    """Parse ``.IN2`` bytes; return the content (``None`` on error) and every problem found."""
    lines = text_lines(raw)  # ASCII up to the end marker; comments after it are Latin-1
    problems: list[Problem] = []

    def err(msg, hint, line):
        problems.append(Problem(msg, hint, file=file, line=line, code="in2"))

    # Significant lines with their 1-based numbers, until the end marker.
    rows = [(i + 1, ln.strip()) for i, ln in enumerate(lines)]
    it = iter([(no, s) for no, s in rows if s])
    try:
        no, first = next(it)
    except StopIteration:
        err("the file is empty", "an .IN2 file starts with the number of tasks", 1)
        return None, problems
    try:
        n = int(first)
        if n < 1:
            raise ValueError
    except ValueError:
        err(f"first line should be the number of tasks, found {first!r}", "an .IN2 file starts with a positive integer", no)
        return None, problems
    durations: list[int | float] = []
    for _ in range(n):
        try:
            no, s = next(it)
        except StopIteration:
            err(f"the file ends after {len(durations)} of {n} task durations", "give one duration per task", len(lines))
            return None, problems
        try:
            d = float(s.replace(",", ".")) if not s.lstrip("-").isdigit() else int(s)
            if d < 0:
                raise ValueError
            durations.append(d)
        except ValueError:
            err(f"task {len(durations) + 1}: duration {s!r} is not a number ≥ 0", "one duration per line", no)
            return None, problems
    pairs: list[tuple[int, int]] = []
    pair_lines: dict[tuple[int, int], int] = {}
    trailer_from = None
    ended = False
    for no, s in it:
        fields = [f.strip() for f in s.split(",")]
        try:
            a, b = (int(f) for f in fields)
        except ValueError:
            err(f"precedence line {s!r} is not 'i,j'", "write one pair of task numbers per line, e.g. 3,7; end with -1,-1", no)
            continue
        if (a, b) == (-1, -1):
            ended = True
            trailer_from = no
            break
        bad = [t for t in (a, b) if not 1 <= t <= n]
        if bad:
            err(f"precedence {a},{b} names task {bad[0]}, but tasks are numbered 1..{n}", "fix the task number", no)
            continue
        if a == b:
            err(f"task {a} requires itself", "remove this line", no)
            continue
        pairs.append((a, b))
        pair_lines.setdefault((a, b), no)
    trailer = "\n".join(lines[trailer_from:]).strip() if ended and trailer_from else ""
    if problems:
        return None, problems
    return In2(n=n, durations=tuple(durations), pairs=tuple(pairs), trailer=trailer, lines=pair_lines), problems


def read_in2(path: str | Path) -> In2:
    """Read an ``.IN2`` file; raise :class:`In2Error` with every problem.

    >>> g = read_in2("../shared/data/salbp/MERTENS.IN2")  # doctest: +SKIP
    >>> g.n, len(g.pairs)                                  # doctest: +SKIP
    (7, 6)
    """
    content, problems = parse_in2(Path(path).read_bytes(), file=str(path))
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
