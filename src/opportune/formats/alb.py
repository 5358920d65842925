"""SALBP-2013 precedence graphs (``.alb``, Otto, Otto & Scholl 2013) read and written as plans.

The format is a list of sections, each a header line ``<name>`` and its values::

    <number of tasks>
    3
    <cycle time>
    10
    <order strength>
    0,667
    <task times>
    1 4
    2 7
    3 2
    <precedence relations>
    1,2
    1,3
    <end>

Tasks are numbered from 1; ``<task times>`` has one line ``task time`` per task
(whole numbers) and ``<precedence relations>`` one line ``i,j`` (task *i*
before task *j*) per arc.  The order strength is the share of task pairs that
are ordered (comparable in the transitive closure), written with a decimal
comma by the original data set; both ``,`` and ``.`` are read.

Reading tolerates blank lines, CRLF/CR ends, a UTF-8 byte-order mark, sections
in any order and unknown sections (a warning; their lines are skipped: the ALB
variants add e.g. ``<number of stations>``).  Text after ``<end>`` is not read (a warning; a
second graph there is an error);
a file without ``<end>`` is refused as truncated.  As with ``.IN2`` files,
parts are named by task number and task times become per-part ``install``
costs; every problem is reported with its file and line, never as a traceback.

Bounds (:mod:`opportune.formats.graphs`), checked before anything large is
built: :data:`~opportune.formats.graphs.MAX_LINES` lines (counted on the
bytes), :data:`~opportune.formats.graphs.MAX_LINE_CHARS` characters a line,
:data:`MAX_TASKS` tasks and :data:`MAX_PAIRS` precedence lines.
"""

from __future__ import annotations

import codecs
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Iterable

from opportune.formats.graphs import (MAX_PAIRS, MAX_PER_KIND, MAX_TASKS, DECIMAL as _DECIMAL, Findings,
                                      GraphFormatError, PAIR as _PAIR, check_graph, file_bytes,
                                      in_file_order as _in_file_order,
                                      last_nonblank as _last_nonblank, show as _show, text_lines, to_int as _int,
                                      too_long, too_many_lines)
from opportune.formats.documents import CheckResult
from opportune.formats.problems import Problem

SECTIONS = ("number of tasks", "cycle time", "order strength", "task times", "precedence relations", "end")
_HEAD = re.compile(rb"\A(?:\xef\xbb\xbf)?\s*<\s*number\s+of\s+tasks\s*>", re.IGNORECASE)
__all__ = ["Alb", "AlbError", "MAX_PAIRS", "MAX_PER_KIND", "MAX_TASKS", "alb_text", "check_alb_bytes", "graph_text",
           "is_alb", "order_strength", "parse_alb", "poset_order_strength", "read_alb", "write_alb"]


@dataclass(frozen=True)
class Alb:
    """The content of an ``.alb`` file: ``pairs`` are distinct 1-based ``(before, after)`` task numbers."""

    n: int
    durations: tuple[int, ...]
    pairs: tuple[tuple[int, int], ...]
    cycle_time: int | None = None
    order_strength: float | None = None
    lines: dict = field(default_factory=dict, compare=False, repr=False)  # (before, after) -> line number
    order_strength_line: int | None = field(default=None, compare=False, repr=False)


class AlbError(GraphFormatError):
    """An ``.alb`` file that cannot be read; ``problems`` lists every problem."""


# ---------------------------------------------------------------- reading


def is_alb(path: str | Path, raw: bytes) -> bool:
    """True for a ``.alb`` suffix (any case) or content that starts with ``<number of tasks>``.  O(1)."""
    return Path(path).suffix.lower() == ".alb" or _HEAD.match(raw[:200]) is not None


def parse_alb(raw: bytes, file: str | None = None) -> tuple[Alb | None, list[Problem]]:
    """Parse ``.alb`` bytes; return the content (``None`` on any error) and every problem found.

    Warnings (unknown sections, repeated pairs) come with a usable content.
    O(size of the file): each line is looked at once, repeated pairs are found
    with a dictionary.
    """
    out = Findings(file, code="alb")
    refused = too_many_lines(raw, file)  # before the lines are built
    if refused:
        return None, refused
    lines = text_lines(raw.removeprefix(codecs.BOM_UTF8))
    sections, end_line = _sections(lines, out)
    last_line = _last_nonblank(lines)
    if end_line is None:
        out.add("the file ends without `<end>`: it is probably truncated",
                "check that the whole file was copied; a complete .alb file ends with a line `<end>`",
                last_line, code="truncated")
    if end_line is not None:
        _after_end(lines, end_line, out)
    where_end = end_line or last_line
    n = _task_count(sections.get("number of tasks"), out)
    cycle_time = _cycle_time(sections.get("cycle time"), out)
    strength, strength_line = _order_strength_value(sections.get("order strength"), out)
    durations = _task_times(sections.get("task times"), n, out, where_end)
    pairs, pair_lines = _precedences(sections.get("precedence relations"), n, out, where_end)
    problems = _in_file_order(out.finish())
    if out.has_errors or n is None:
        return None, problems
    content = Alb(n=n, durations=tuple(durations), pairs=tuple(pairs), cycle_time=cycle_time,
                  order_strength=strength, lines=pair_lines, order_strength_line=strength_line)
    return content, problems


def read_alb(path: str | Path) -> Alb:
    """Read an ``.alb`` file; raise :class:`AlbError` with every problem (warnings are dropped)."""
    content, problems = parse_alb(file_bytes(path, AlbError), file=str(path))
    if content is None:
        raise AlbError([p for p in problems if p.severity == "error"])
    return content


def check_alb_bytes(raw: bytes, *, file: str | None = None) -> CheckResult:
    """Read ``.alb`` bytes as a single-strategy plan (parts '1'..'n'), checked like any plan.

    Besides the checks of every plan (cycles, redundant arcs), a stated order
    strength that disagrees with the precedence relations is a warning.
    """
    content, problems = parse_alb(raw, file)
    if content is None:
        return CheckResult(None, problems)
    checked = check_graph(content.durations, content.pairs, content.lines, file=file,
                          source="SALBP-2013 precedence graph", default_name="alb")
    problems = problems + checked.problems
    if checked.plan is not None and content.order_strength is not None:
        problems += _strength_mismatch(content, file)
    return CheckResult(checked.plan, _in_file_order(problems))


def _after_end(lines: list[str], end_line: int, out: Findings) -> None:
    """Text after ``<end>``: a second graph is an error (one graph per file), anything else a warning
    (it is not read).  O(lines after it)."""
    rest = [(no, s.strip()) for no, s in enumerate(lines[end_line:], end_line + 1) if s.strip()]
    if not rest:
        return
    no, first = rest[0]
    header = next(((n, t) for n, t in rest if " ".join(t.lower().split()) == "<number of tasks>"), None)
    if header is not None:
        out.add(f"a second graph starts at line {header[0]}, after `<end>` at line {end_line}",
                "an .alb file holds one graph: put each graph in a file of its own", header[0],
                code="second-graph")
    else:
        out.add(f"{len(rest):,} line{'s' if len(rest) > 1 else ''} after `<end>` (from {_show(first)}) "
                f"{'are' if len(rest) > 1 else 'is'} not read", "remove them, or move the values they hold above `<end>`", no,
                code="after-end", severity="warning")


@dataclass
class _Section:
    name: str
    line: int
    rows: list[tuple[int, str]] = field(default_factory=list)  # (line number, stripped text)


def _sections(lines: list[str], out: Findings) -> tuple[dict[str, _Section], int | None]:
    """The non-blank lines grouped under their known section headers, up to ``<end>``, and the line of ``<end>``.

    O(number of lines).  Unknown sections warn and are skipped; a repeated
    section is an error (its lines are skipped); values before the first
    header are errors.
    """
    sections: dict[str, _Section] = {}
    current: _Section | None = None
    skipping = False  # inside an unknown or repeated section: its lines are not ours to judge
    for no, text in enumerate(lines, 1):
        s = text.strip()
        if not s or too_long(s, no, out):  # a line of megabytes would be split into millions of strings
            continue
        if s.startswith("<") and s.endswith(">"):
            name = " ".join(s[1:-1].lower().split())
            current, skipping = None, True
            if name == "end":
                return sections, no
            if name not in SECTIONS:
                out.add(f"unknown section {_show(s)}: its lines are ignored",
                        "this reader knows " + ", ".join(f"<{x}>" for x in SECTIONS), no,
                        code="unknown-section", severity="warning")
            elif name in sections:
                out.add(f"section <{name}> appears twice (first at line {sections[name].line})",
                        "merge the two sections into one", no, code="duplicate-section")
            else:
                current = sections[name] = _Section(name, no)
                skipping = False
            continue
        if current is not None:
            current.rows.append((no, s))
        elif not skipping:
            out.add(f"{_show(s)} comes before any section header",
                    "an .alb file starts with a line `<number of tasks>`; every value goes under its section", no)
    return sections, None


def _single_value(sec: _Section, out: Findings) -> tuple[int, str] | None:
    """The one value line of a scalar section, or ``None`` (reported) if there is none."""
    if not sec.rows:
        out.add(f"<{sec.name}> has no value", "write the value on the line after the header", sec.line)
        return None
    for no, s in sec.rows[1:]:
        out.add(f"<{sec.name}> takes one value; {_show(s)} is one too many",
                "remove this line, or put it under the section it belongs to", no)
    return sec.rows[0]


def _task_count(sec: _Section | None, out: Findings) -> int | None:
    if sec is None:
        out.add("no <number of tasks> section",
                "an .alb file starts with a line `<number of tasks>` and the number on the next line", 1,
                code="missing-section")
        return None
    row = _single_value(sec, out)
    if row is None:
        return None
    no, s = row
    n = _int(s)
    if n is None or n < 1:
        out.add(f"the number of tasks must be a whole number ≥ 1, found {_show(s)}", "write e.g. `20`", no)
        return None
    if n > MAX_TASKS:
        out.add(f"{n:,} tasks is more than this reader accepts ({MAX_TASKS:,})",
                "split the graph into smaller ones", no, code="limit")
        return None
    return n


def _cycle_time(sec: _Section | None, out: Findings) -> int | None:
    row = _single_value(sec, out) if sec is not None else None
    if row is None:
        return None
    value = _int(row[1])
    if value is None or value < 1:
        out.add(f"the cycle time must be a whole number ≥ 1, found {_show(row[1])}", "write e.g. `1000`", row[0])
        return None
    return value


def _order_strength_value(sec: _Section | None, out: Findings) -> tuple[float | None, int | None]:
    """The stated order strength and its line (``None``s if absent or bad)."""
    row = _single_value(sec, out) if sec is not None else None
    if row is None:
        return None, None
    no, s = row
    value = float(s.replace(",", ".")) if _DECIMAL.fullmatch(s) else None
    if value is None or not 0 <= value <= 1:
        out.add(f"the order strength must be a number from 0 to 1, found {_show(s)}",
                "write e.g. `0,268` (or `0.268`), or remove the section: it is recomputed from the relations", no)
        return None, None
    return value, no


def _task_times(sec: _Section | None, n: int | None, out: Findings, where_end: int) -> list[int]:
    """Task times in task order (0 where missing: then there is an error).  O(lines of the section)."""
    if sec is None:
        out.add("no <task times> section", "add `<task times>` with one line `task time` per task", where_end,
                code="missing-section")
        return []
    times = [0] * (n or 0)
    first: dict[int, int] = {}
    for no, s in sec.rows:
        fields = s.split()
        if len(fields) != 2:
            out.add(f"task times line {_show(s)} is not 'task time'",
                    "write the task number and its time, e.g. `3 17`", no)
            continue
        task, time = _int(fields[0]), _int(fields[1])
        if task is None:
            out.add(f"task number {_show(fields[0])} is not a whole number", "write e.g. `3 17`", no)
            continue
        if n is not None and not 1 <= task <= n:
            out.add(f"task {task} is out of range: tasks are numbered 1..{n}",
                    "fix the task number, or the number of tasks", no, parts=(str(task),))
            continue
        if task in first:
            out.add(f"task {task} has a second time (first at line {first[task]})", "keep one line per task", no,
                    parts=(str(task),))
            continue
        first[task] = no  # even with a bad time: its absence is not a second problem
        if time is None or time < 0:
            out.add(f"task {task}: time {_show(fields[1])} is not a whole number ≥ 0",
                    "task times in .alb files are whole numbers", no, parts=(str(task),))
            continue
        if n is not None:
            times[task - 1] = time
    if n is not None and len(first) < n:
        missing = [t for t in range(1, n + 1) if t not in first]
        out.add(f"no time for {len(missing)} of the {n} tasks: {_few(missing)}",
                "give one line `task time` per task (a file cut short lacks the last ones)", sec.line,
                parts=tuple(map(str, missing[:10])))
    return times


def _precedences(sec: _Section | None, n: int | None, out: Findings,
                 where_end: int) -> tuple[list[tuple[int, int]], dict[tuple[int, int], int]]:
    """Distinct precedence pairs in file order and the line of each.  O(lines of the section).

    A repeated pair is one warning (with its count), however often it repeats.
    """
    if sec is None:
        out.add("no <precedence relations> section: the tasks are unordered",
                "add `<precedence relations>` (it may stay empty if the tasks really are unordered)", where_end,
                code="missing-section", severity="warning")
        return [], {}
    first: dict[tuple[int, int], int] = {}
    repeats: dict[tuple[int, int], list[int]] = {}  # pair -> [count, line of the first repeat]
    known: dict[str, tuple[int, int]] = {}  # text of an accepted line -> its pair: a repeated line costs one lookup
    for k, (no, s) in enumerate(sec.rows):
        if k == MAX_PAIRS:
            out.add(f"more than {MAX_PAIRS:,} precedence relations", "split the graph into smaller ones", no,
                    code="limit")
            break
        pair = known.get(s)
        if pair is None:
            match = _PAIR.fullmatch(s)
            if match is None:
                out.add(f"precedence line {_show(s)} is not 'i,j'",
                        "write one pair of task numbers per line, e.g. `3,7` (task 3 before task 7)", no)
                continue
            a, b = int(match[1]), int(match[2])
            if n is not None and not (1 <= a <= n and 1 <= b <= n):
                bad = a if not 1 <= a <= n else b
                out.add(f"precedence {a},{b} names task {bad}, but tasks are numbered 1..{n}", "fix the task number",
                        no, parts=(str(a), str(b)))
                continue
            if a == b:
                out.add(f"task {a} is required before itself", "remove this line", no, parts=(str(a),))
                continue
            pair = (a, b)
            if pair not in first:
                first[pair] = no
                known[s] = pair
                continue
        seen = repeats.get(pair)
        if seen is None:
            repeats[pair] = [1, no]
        else:
            seen[0] += 1
    for (a, b), (count, line) in repeats.items():
        times = "once" if count == 1 else f"{count:,} times"
        out.add(f"precedence {a},{b} is repeated {times} (first at line {first[(a, b)]}); the repeats are ignored",
                "remove the repeated lines", line, code="repeated", severity="warning", parts=(str(a), str(b)))
    return list(first), first


def _strength_mismatch(content: Alb, file: str | None) -> list[Problem]:
    """A warning if the stated order strength is not the relations' own (beyond the 3 decimals written)."""
    actual = order_strength(content.n, content.pairs)
    if abs(actual - content.order_strength) <= 0.0015:
        return []
    return [Problem(f"the file states order strength {content.order_strength:.3f} but its precedence relations "
                    f"give {actual:.3f}",
                    "the stated value is not used; correct it (write_alb writes the computed one)",
                    file=file, line=content.order_strength_line, severity="warning", code="order-strength")]


def _few(tasks: list[int], k: int = 10) -> str:
    return ", ".join(map(str, tasks[:k])) + (", ..." if len(tasks) > k else "")


# ---------------------------------------------------------------- order strength


def order_strength(n: int, pairs: Iterable[tuple[int, int]]) -> float:
    """Order strength of tasks ``1..n`` ordered by 1-based ``(before, after)`` pairs.

    The number of comparable pairs of the transitive closure divided by
    n(n-1)/2 (0.0 for fewer than two tasks).  O(n + len(pairs)) big-int
    operations on n-bit masks; raises
    :class:`~opportune.planning.orders.CycleError` on a cycle.

    >>> order_strength(3, [(1, 2), (2, 3)]), order_strength(3, [(1, 2)])
    (1.0, 0.3333333333333333)
    """
    from opportune.planning.orders import StrategyOrder

    total = n * (n - 1) // 2
    return StrategyOrder([(a - 1, b - 1) for a, b in pairs]).implied / total if total else 0.0


def poset_order_strength(poset) -> float:
    """Order strength of an engine :class:`~opportune.engine.poset.Poset`: O(n) popcounts."""
    total = poset.n * (poset.n - 1) // 2
    return sum(m.bit_count() for m in poset.above) / total if total else 0.0


# ---------------------------------------------------------------- writing


def write_alb(plan, path_or_file: str | Path | IO, *, cycle_time: int | None = None) -> None:
    """Write a single-strategy plan of quantity-1 parts as an ``.alb`` file.

    Part *k* in declaration order becomes task *k* (1-based); its ``install``
    cost (default 1) is the task time and must be a whole number.  The arcs
    written are the transitive reduction of the strategy's order (same
    admissible sequences, no redundant arc); the order strength is computed
    and written to 3 decimals with the data set's decimal comma.  The plan has
    no cycle time: ``cycle_time`` defaults to the longest task time (the
    smallest feasible one).  ``path_or_file`` is a path or an open text (or
    binary) file.  Raises ``ValueError`` for a plan the format cannot hold.
    Cost: one transitive closure and reduction, O(n + pairs) big-int operations.
    """
    text = alb_text(plan, cycle_time=cycle_time)
    if hasattr(path_or_file, "write"):
        try:
            path_or_file.write(text)
        except TypeError:  # a binary file
            path_or_file.write(text.encode("ascii"))
    else:
        Path(path_or_file).write_text(text, encoding="ascii")


def alb_text(plan, *, cycle_time: int | None = None) -> str:
    """The ``.alb`` text of a plan (see :func:`write_alb`)."""
    times = _alb_times(plan)  # first: it refuses the plans the format cannot hold
    pairs = [(a + 1, b + 1) for a, b in plan.index_pairs(plan.strategies[0])]
    return graph_text(times, pairs, cycle_time=cycle_time)


def graph_text(times: list[int], pairs: Iterable[tuple[int, int]], *, cycle_time: int | None = None) -> str:
    """The ``.alb`` text of tasks ``1..len(times)`` ordered by 1-based ``(before, after)`` pairs.

    Writes the transitive reduction of the pairs (sorted) and the order
    strength of their closure; ``cycle_time`` defaults to the longest time.
    O(n + pairs) big-int operations; ``ValueError`` beyond the reader's limits.
    """
    from opportune.planning.orders import StrategyOrder

    n = len(times)
    if n > MAX_TASKS:
        raise ValueError(f"{n:,} tasks: .alb readers here accept at most {MAX_TASKS:,}")
    order = StrategyOrder([(a - 1, b - 1) for a, b in pairs])
    arcs = order.cover_pairs()
    if len(arcs) > MAX_PAIRS:
        raise ValueError(f"{len(arcs):,} precedence arcs: .alb readers here accept at most {MAX_PAIRS:,}")
    if cycle_time is None:
        cycle_time = max(list(times) + [1])
    if not isinstance(cycle_time, int) or cycle_time < 1:
        raise ValueError(f"cycle_time must be a whole number ≥ 1, got {cycle_time!r}")
    total = n * (n - 1) // 2
    strength = f"{order.implied / total if total else 0.0:.3f}".replace(".", ",")
    lines = ["<number of tasks>", str(n), "", "<cycle time>", str(cycle_time), "", "<order strength>", strength, "",
             "<task times>", *(f"{k} {t}" for k, t in enumerate(times, 1)), "",
             "<precedence relations>", *(f"{a + 1},{b + 1}" for a, b in arcs), "", "<end>", ""]
    return "\n".join(lines)


def _alb_times(plan) -> list[int]:
    """The task times of a plan the format can hold; ``ValueError`` saying why otherwise."""
    if len(plan.strategies) != 1:
        raise ValueError(f"plan {plan.name!r} has {len(plan.strategies)} strategies; an .alb file holds one "
                         "precedence graph: write each strategy as its own plan, or use YAML")
    several = [p.id for p in plan.parts if p.quantity != 1]
    if several:
        raise ValueError(f"an .alb task is one operation, but {_few(several, 5)} ha{'s' if len(several) == 1 else 've'} "
                         "quantity > 1: declare each unit as its own part, or use YAML")
    times = []
    for p in plan.parts:
        t = p.install
        if not (math.isfinite(t) and t >= 0 and float(t).is_integer()):
            raise ValueError(f"part {p.id!r} has install {t!r}, but .alb task times are whole numbers ≥ 0: "
                             "round the install costs, or use YAML")
        times.append(int(t))
    return times
