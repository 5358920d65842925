"""Sequences files: observed assembly sequences, one per line (the input of ``opportune learn``).

Text, UTF-8: part ids separated by spaces or commas, one complete sequence per line; ``#`` starts a
comment; blank lines are skipped.  Every sequence must install the same parts as the first one, each
the same number of times: an id repeated ``k`` times stands for ``k`` identical units of one part
(a part with ``quantity: k`` in the learned plan).

Limits (each refused with a message naming the file, and the line where there is one, before what
it bounds is built): ``MAX_SEQUENCE_BYTES`` (32 MiB) per file, ``MAX_SEQUENCES`` (100,000) sequences
per file, ``MAX_SEQUENCE_ITEMS`` (2,000,000) installations in all, ``MAX_SEQUENCE_LINES``
(1,000,000) lines, counted before any is built, and ``MAX_SEQUENCE_LINE_CHARS`` (1,000,000)
characters a line; per sequence the plan limits of :mod:`opportune.planning.plan` (``MAX_UNITS`` = 10,000
installations, ``MAX_PARTS`` parts).  A part id seen again is the same string: memory grows with the
installations (8 bytes each), not with the bytes of the file.

>>> seqs = parse_sequences("# two runs\\nca ba rl\\nca, rl, ba\\n", file="runs.seq")
>>> seqs.sequences, seqs.lines, seqs.quantities
((('ca', 'ba', 'rl'), ('ca', 'rl', 'ba')), (2, 3), {'ca': 1, 'ba': 1, 'rl': 1})
"""

from __future__ import annotations

import re
import sys
from collections import Counter as Multiset
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from opportune.formats.problems import CONTROL_CHARS, Problem
from opportune.planning.plan import MAX_PARTS, MAX_UNITS
from opportune.limits import MAX_SEQUENCE_BYTES, MAX_SEQUENCE_ITEMS, MAX_SEQUENCES  # noqa: F401 (their home: the one table of limits)

__all__ = ["MAX_SEQUENCE_BYTES", "MAX_SEQUENCE_ITEMS", "MAX_SEQUENCE_LINE_CHARS", "MAX_SEQUENCE_LINES", "MAX_SEQUENCES",
           "SequenceError", "Sequences", "parse_sequences",
           "read_sequences", "sequences_from"]

MAX_SEQUENCE_LINES = 1_000_000  # lines of one file, comments and blank lines included
MAX_SEQUENCE_LINE_CHARS = 1_000_000  # characters of one line (10,000 installations of ids up to 99 characters)
# What str.splitlines splits on: counted before any line is built.
_LINE_BREAKS = ("\n", "\r", "\x0b", "\x0c", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029")
_SURROGATE = re.compile("[\ud800-\udfff]")
#: Control characters no part id may hold (as plans refuse them): C0, DEL and C1.
_CONTROL = re.compile(f"[{CONTROL_CHARS}]")
_SPLIT = re.compile(r"[\s,]+")


class SequenceError(ValueError):
    """A sequences file (or list) that cannot be used; ``problem`` says where and what to do."""

    def __init__(self, problem: Problem):
        self.problem = problem
        super().__init__(str(problem))


@dataclass(frozen=True)
class Sequences:
    """Observed sequences of one part set, checked.

    ``sequences[i]`` is a tuple of part ids (a part with several units repeats); ``lines[i]`` is its
    1-based line in ``file`` (or its 1-based position when it did not come from a file);
    ``quantities`` maps each part, in order of first appearance in the first sequence, to its units.
    """

    sequences: tuple[tuple[str, ...], ...]
    lines: tuple[int, ...]
    quantities: dict
    file: str | None = None

    def __len__(self) -> int:
        return len(self.sequences)

    def where(self, i: int) -> str:
        """Where sequence ``i`` came from: ``file:line``, or ``sequence N``."""
        return f"{self.file}:{self.lines[i]}" if self.file else f"sequence {self.lines[i]}"


def _shown(value: str) -> str:
    text = ascii(value) if not value.isprintable() or not value.isascii() else f"'{value}'"
    return text if len(text) <= 60 else text[:57] + "..."


def _count(n: int, what: str) -> str:
    return f"{'once' if n == 1 else 'twice' if n == 2 else f'{n} times'}" if what == "times" else f"{n} {what}"


def _check_line(tokens: tuple[str, ...], no: int, file: str | None, reference: Multiset | None,
                ref_where: str) -> Multiset:
    """The multiset of ``tokens``, after checking it against the limits and ``reference``."""
    line = no if file else None
    where = "" if file else f"sequence {no}: "
    if not tokens:
        raise SequenceError(Problem(f"{where}an empty sequence", "list the parts in the order they were installed",
                                    file=file, line=line, code="empty"))
    if len(tokens) > MAX_UNITS:
        raise SequenceError(Problem(f"{where}{len(tokens):,} installations in one sequence; at most {MAX_UNITS:,} "
                                    "(the plan limit)", "learn from a smaller product", file=file, line=line,
                                    code="limit"))
    for t in tokens:
        if _SURROGATE.search(t):
            raise SequenceError(Problem(f"{where}{_shown(t)} is not valid Unicode text", "write part ids as text",
                                        file=file, line=line, code="text"))
        control = _CONTROL.search(t)
        if control:
            raise SequenceError(Problem(f"{where}{_shown(t)} contains the control character "
                                        f"U+{ord(control.group()):04X}", "write part ids as printable text",
                                        file=file, line=line, code="text"))
    counts = Multiset(tokens)
    if len(counts) > MAX_PARTS:
        raise SequenceError(Problem(f"{where}{len(counts):,} different parts; at most {MAX_PARTS:,}", "",
                                    file=file, line=line, code="limit"))
    if reference is None:
        return counts
    hint = (f"every sequence must install the same parts as the first one ({ref_where}), each as many times "
            "(a repeated id stands for identical units of one part)")
    for part, k in counts.items():
        if part not in reference:
            raise SequenceError(Problem(f"{where}unknown part {_shown(part)}: the first sequence ({ref_where}) has "
                                        "no such part", hint, file=file, line=line, parts=(part,), code="unknown-part"))
        if k != reference[part]:
            raise SequenceError(Problem(f"{where}part {_shown(part)} appears {_count(k, 'times')}, in the first "
                                        f"sequence ({ref_where}) {_count(reference[part], 'times')}", hint, file=file,
                                        line=line, parts=(part,), code="duplicate-part" if k > reference[part]
                                        else "missing-part"))
    for part in reference:
        if part not in counts:
            raise SequenceError(Problem(f"{where}part {_shown(part)} is missing (the first sequence, {ref_where}, "
                                        "installs it)", hint, file=file, line=line, parts=(part,),
                                        code="missing-part"))
    return counts


def sequences_from(items: Iterable[tuple[int, tuple[str, ...]]], *, file: str | None = None,
                   like: Sequences | None = None, what: str = "sequences") -> Sequences:
    """Check ``(line, sequence)`` pairs and build :class:`Sequences`; with ``like``, every sequence must
    have ``like``'s parts (a failed sequence against the successes).  O(total length).

    Raises :class:`SequenceError` naming the line of the first bad sequence.
    """
    reference = Multiset(like.quantities) if like is not None and like.sequences else None
    ref_where = like.where(0) if reference is not None else ""
    seqs, lines, quantities = [], [], None
    for no, seq in items:
        if len(seqs) >= MAX_SEQUENCES:
            raise SequenceError(Problem(f"more than {MAX_SEQUENCES:,} {what}", f"give at most {MAX_SEQUENCES:,} "
                                        "(a sample of them is enough: see the learning curve in docs/learn.md)",
                                        file=file, line=no if file else None, code="limit"))
        counts = _check_line(seq, no, file, reference, ref_where)
        if reference is None:
            reference, ref_where = counts, (f"{file}:{no}" if file else f"sequence {no}")
            quantities = {p: counts[p] for p in dict.fromkeys(seq)}
        seqs.append(seq)
        lines.append(no)
    if quantities is None:
        quantities = dict(like.quantities) if like is not None else {}
    return Sequences(tuple(seqs), tuple(lines), quantities, file)


def parse_sequences(text: str, *, file: str | None = None, like: Sequences | None = None,
                    what: str = "sequences") -> Sequences:
    """Parse a sequences file's text and check it (see the module docstring); O(length of the text).

    Raises :class:`SequenceError` with the file and line of the first problem.

    >>> try:
    ...     parse_sequences("a b\\nb\\n", file="x.seq")
    ... except SequenceError as exc:
    ...     print(exc.problem.where, exc.problem.message)
    x.seq:2 part 'a' is missing (the first sequence, x.seq:1, installs it)
    """

    lines = sum(text.count(c) for c in _LINE_BREAKS) - text.count("\r\n")
    if lines > MAX_SEQUENCE_LINES:
        raise SequenceError(Problem(f"more than {MAX_SEQUENCE_LINES:,} lines; sequences files of at most "
                                    f"{MAX_SEQUENCE_LINES:,} lines are read", "learn from a sample of the sequences",
                                    file=file, line=MAX_SEQUENCE_LINES + 1 if file else None, code="limit"))
    same: dict[str, str] = {}  # each id once in memory, however often it is installed

    def items():
        total = 0
        for no, line in enumerate(text.splitlines(), start=1):
            if len(line) > MAX_SEQUENCE_LINE_CHARS:
                raise SequenceError(Problem(f"a line of {len(line):,} characters; lines of at most "
                                            f"{MAX_SEQUENCE_LINE_CHARS:,} are read", "one sequence per line",
                                            file=file, line=no if file else None, code="limit"))
            tokens = tuple(same.setdefault(t, t) for t in _SPLIT.split(line.split("#", 1)[0]) if t)
            if tokens:
                total += len(tokens)
                if total > MAX_SEQUENCE_ITEMS:
                    raise SequenceError(Problem(f"more than {MAX_SEQUENCE_ITEMS:,} installations in all; sequences "
                                                f"files of at most {MAX_SEQUENCE_ITEMS:,} are read",
                                                "learn from a sample of the sequences", file=file,
                                                line=no if file else None, code="limit"))
                yield no, tokens

    return sequences_from(items(), file=file, like=like, what=what)


def read_sequences(source: str | Path, *, like: Sequences | None = None, what: str = "sequences") -> Sequences:
    """Read and check a sequences file.  Reads at most ``MAX_SEQUENCE_BYTES``; O(size of the file).

    Parameters
    ----------
    source : str or Path
        A :class:`~pathlib.Path` or a file name; ``-`` for standard input; ``example:NAME`` for a shipped
        example (``src/opportune/datasets/examples/NAME.seq``); a ``str`` holding a newline is the text itself.
    like : Sequences, optional
        Sequences the new ones must match (the same parts, as many units each): the successes, when
        reading the failures.
    what : str
        What the sequences are, as the messages name them.

    Returns
    -------
    Sequences
        The sequences (tuples of part ids), their lines, each part's units and the file.

    Raises
    ------
    SequenceError
        A missing or unreadable file, one over the size limit or not UTF-8, an unknown example, or
        sequences that do not match (every problem with its line).

    Examples
    --------
    >>> len(read_sequences("example:gearbox-observed"))
    12
    >>> read_sequences("a b c\\nb a c\\n").quantities
    {'a': 1, 'b': 1, 'c': 1}
    >>> read_sequences("example:nothing")     # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    opportune.formats.sequences.SequenceError: error: no example sequences named 'nothing': ...
    """
    if isinstance(source, str) and "\n" in source:
        return parse_sequences(source, like=like, what=what)
    name = str(source)
    shown = None
    if name.lower().startswith("example:"):
        path, shown = _example(name[len("example:"):]), name
    elif name == "-":
        raw = sys.stdin.buffer.read(MAX_SEQUENCE_BYTES + 1)
        return parse_sequences(_decode(raw, "<stdin>"), file="<stdin>", like=like, what=what)
    else:
        path = Path(source)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_SEQUENCE_BYTES + 1)
    except FileNotFoundError:
        raise SequenceError(Problem(f"no such file: {path}", "check the path ('-' reads standard input)",
                                    file=str(path), code="io")) from None
    except OSError as exc:
        raise SequenceError(Problem(f"cannot read {path}: {exc.strerror or exc}", "give a text file",
                                    file=str(path), code="io")) from None
    shown = shown or str(path)
    return parse_sequences(_decode(raw, shown), file=shown, like=like, what=what)


def _decode(raw: bytes, file: str) -> str:
    if len(raw) > MAX_SEQUENCE_BYTES:
        raise SequenceError(Problem(f"larger than {MAX_SEQUENCE_BYTES:,} bytes; sequences files of at most "
                                    f"{MAX_SEQUENCE_BYTES:,} bytes are read", "learn from a sample of the sequences",
                                    file=file, code="limit"))
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise SequenceError(Problem("not UTF-8 text", "save the file as UTF-8", file=file, line=line,
                                    code="text")) from None


def _example(name: str) -> Path:
    """A shipped sequences file, by name (``gearbox-observed``; the ``.seq`` suffix is optional)."""
    from opportune.formats.shipped import shipped_folder

    folder = shipped_folder("examples")
    stem = name.removesuffix(".seq")
    entry = folder.joinpath(f"{stem}.seq")
    if stem and "/" not in stem and "\\" not in stem and entry.is_file():
        return Path(str(entry))
    names = sorted(e.name[:-4] for e in folder.iterdir() if e.name.endswith(".seq"))
    raise SequenceError(Problem(f"no example sequences named '{name}': the package ships "
                                f"{', '.join(names) or 'none'}", "e.g. example:gearbox-observed", code="io"))
