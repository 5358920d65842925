"""What the precedence-graph readers share (SALBP ``.IN2`` and SALBP-2013 ``.alb``).

Both formats describe one partial order over tasks ``1..n`` with a duration per
task.  Each reader parses its own syntax into (durations, pairs, the line of
each pair); :func:`check_graph` turns that into a single-strategy plan checked
like any plan file (cycles, redundant constraints), with every problem placed
on the line of the file that caused it.
"""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path
from typing import Sequence

from opportune.formats.documents import CheckResult, file_stem  # noqa: F401 (file_stem: its former home)
from opportune.formats.problems import Problem
# Limits of the graph readers (.IN2, .alb, DOT, GraphML; their values in the one table, opportune.limits),
# checked while reading, before anything is built from the file; each keeps the largest file accepted
# loaded within 5 s of CPU time and 500 MB.  A graph read is then a plan like any other, limited to
# MAX_UNITS tasks (opportune.planning.plan).
from opportune.limits import MAX_LINE_CHARS, MAX_LINES, MAX_PAIRS, MAX_TASKS  # noqa: F401,E402
# A garbage file could give a problem per line; past this many of one kind, one line sums up the rest.
MAX_PER_KIND = 50
INT = re.compile(r"[+-]?[0-9]{1,18}")  # ASCII digits only: str.isdigit() would accept '²'
PAIR = re.compile(r"([+-]?[0-9]{1,18})\s*,\s*([+-]?[0-9]{1,18})")  # the line is stripped already
DECIMAL = re.compile(r"[+-]?(?:[0-9]{1,18}(?:[.,][0-9]{0,18})?|[.,][0-9]{1,18})")


class GraphFormatError(ValueError):
    """A precedence-graph file that cannot be read, with every problem found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(map(str, problems)))


def file_bytes(path: str | Path, error: type[GraphFormatError]) -> bytes:
    """The bytes of a graph file, reading at most :data:`~opportune.formats.loader.MAX_FILE_BYTES`
    (and one more, to know): a larger file raises ``error`` with the bound, unread."""
    from opportune.formats.documents import MAX_FILE_BYTES

    with Path(path).open("rb") as f:
        raw = f.read(MAX_FILE_BYTES + 1)
    if len(raw) > MAX_FILE_BYTES:
        raise error([Problem(f"{path} is larger than {MAX_FILE_BYTES:,} bytes; graph files of at most "
                             f"{MAX_FILE_BYTES:,} bytes are read", "split the graph into smaller ones",
                             file=str(path), code="limit")])
    return raw


def text_lines(raw: bytes) -> list[str]:
    """The lines of a graph file, whichever of CRLF, CR or LF ends them.  O(len(raw)).

    Decoded as Latin-1, which accepts every byte: the data are ASCII, and free
    text after the end marker of real files is often Latin-1.  Call
    :func:`too_many_lines` first: the list costs about 60 bytes a line.
    """
    return raw.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n").split("\n")


def too_many_lines(raw: bytes, file: str | None) -> list[Problem]:
    """The refusal of a line-based graph file of more than :data:`MAX_LINES` lines, or ``[]``.

    Counted on the bytes (``bytes.count``: C speed, nothing built) before the file is split into
    lines; a line break is LF, CR or CRLF, as for :func:`text_lines`.
    """
    lines = raw.count(b"\n") + raw.count(b"\r") - raw.count(b"\r\n")
    if lines <= MAX_LINES:
        return []
    return [Problem(f"the file has {lines + 1:,} lines; graph files of at most {MAX_LINES:,} lines are read "
                    f"({MAX_TASKS:,} tasks and {MAX_PAIRS:,} precedence lines at most)",
                    "split the graph into smaller ones, or remove the blank lines", file=file, line=MAX_LINES + 1,
                    code="limit")]


def too_long(s: str, no: int, out: "Findings") -> bool:
    """True (and the problem added to ``out``) if line ``no`` is longer than :data:`MAX_LINE_CHARS`."""
    if len(s) <= MAX_LINE_CHARS:
        return False
    out.add(f"line of {len(s):,} characters; lines of at most {MAX_LINE_CHARS:,} are read here",
            "one value or one pair per line", no, code="limit")
    return True


def show(s: str, width: int = 40) -> str:
    """A value quoted for a message, cut short (a mangled line can be megabytes long), every character
    that is not printable ASCII escaped (``'\\xff\\xfe'``): bytes that are not text are described, never
    printed raw to a terminal or a log."""
    return ascii(s if len(s) <= width else s[: width - 3] + "...")


def to_int(s: str) -> int | None:
    """A whole number written in ASCII digits (at most 18 of them), or None."""
    return int(s) if INT.fullmatch(s) else None


def last_nonblank(lines: list[str]) -> int:
    """The 1-based number of the last line that is not blank (1 for a blank file)."""
    for i in range(len(lines) - 1, -1, -1):
        if lines[i].strip():
            return i + 1
    return 1


class Findings:
    """The problems of one file, at most :data:`MAX_PER_KIND` per code and severity, then one summary."""

    def __init__(self, file: str | None, code: str = "graph"):
        self.file = file
        self.code = code
        self.problems: list[Problem] = []
        self.has_errors = False
        self._seen: Counter = Counter()
        self._first_dropped: dict[tuple[str, str], int | None] = {}

    def add(self, message: str, hint: str, line: int | None, *, code: str | None = None, severity: str = "error",
            parts: tuple[str, ...] = ()) -> None:
        code = code or self.code
        self.has_errors |= severity == "error"
        key = (code, severity)
        self._seen[key] += 1
        if self._seen[key] > MAX_PER_KIND:
            self._first_dropped.setdefault(key, line)
            return
        self.problems.append(Problem(message, hint, file=self.file, line=line, parts=parts, severity=severity, code=code))

    def finish(self) -> list[Problem]:
        for (code, severity), line in self._first_dropped.items():
            more = self._seen[(code, severity)] - MAX_PER_KIND
            self.problems.append(Problem(f"{more} more problems like the ones above ({code}), the first of them here",
                                         "fix the ones listed and check again", file=self.file, line=line,
                                         severity=severity, code=code))
        return self.problems


def in_file_order(problems: list[Problem]) -> list[Problem]:
    """Errors first, each kind by line (as :func:`~opportune.formats.validate.check_document` orders them)."""
    return sorted(problems, key=lambda p: (p.severity != "error", p.line or 0))


def check_graph(
    durations: Sequence[int | float],
    pairs: Sequence[tuple[int, int]],
    pair_lines: dict[tuple[int, int], int],
    *,
    file: str | None,
    source: str,
    default_name: str,
) -> CheckResult:
    """Check tasks ``1..len(durations)`` ordered by 1-based ``(before, after)`` pairs as a plan.

    Parts are named by task number and a task's duration is its ``install``
    cost.  The plan goes through the same checks as a plan file
    (:func:`~opportune.formats.validate.check_document`); the problems it finds
    are moved to the file line of the pair they name (``pair_lines``), since the
    lines of the document built here are not lines of the file.  Cost: that of
    ``check_document`` on the graph.
    """
    from opportune.formats.documents import Document
    from opportune.formats.validate import check_document

    requires: dict[str, list[str]] = {}
    for a, b in pairs:
        requires.setdefault(str(b), []).append(str(a))
    data = {
        "name": file_stem(file) if file else default_name,
        "source": f"{source} {Path(file).name if file else ''}".strip(),
        "parts": [{"id": str(i + 1), "install": d} for i, d in enumerate(durations)],
        "requires": requires,
    }
    result = check_document(Document(data, {}, file))

    def line_of(p: Problem):
        if len(p.parts) >= 2 and all(x.isdigit() for x in p.parts[:2]):
            return pair_lines.get((int(p.parts[0]), int(p.parts[1])))
        return None

    cleaned = [Problem(p.message, p.hint, file=p.file, line=line_of(p), parts=p.parts, severity=p.severity, code=p.code)
               for p in result.problems]
    return CheckResult(result.plan, cleaned)
