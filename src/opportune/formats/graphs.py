"""What the precedence-graph readers share (SALBP ``.IN2`` and SALBP-2013 ``.alb``).

Both formats describe one partial order over tasks ``1..n`` with a duration per
task.  Each reader parses its own syntax into (durations, pairs, the line of
each pair); :func:`check_graph` turns that into a single-strategy plan checked
like any plan file (cycles, redundant constraints), with every problem placed
on the line of the file that caused it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from opportune.formats.loader import CheckResult
from opportune.formats.problems import Problem


class GraphFormatError(ValueError):
    """A precedence-graph file that cannot be read, with every problem found."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(map(str, problems)))


def text_lines(raw: bytes) -> list[str]:
    """The lines of a graph file, whichever of CRLF, CR or LF ends them.  O(len(raw)).

    Decoded as Latin-1, which accepts every byte: the data are ASCII, and free
    text after the end marker of real files is often Latin-1.
    """
    return raw.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n").split("\n")


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
    from opportune.formats.loader import Document
    from opportune.formats.validate import check_document

    requires: dict[str, list[str]] = {}
    for a, b in pairs:
        requires.setdefault(str(b), []).append(str(a))
    data = {
        "name": Path(file).stem if file else default_name,
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
