"""Looks files: what the vision system saw, one look per line.

Text: part ids separated by spaces or commas, ``-`` for an empty look,
``#`` starts a comment, blank lines are skipped.  JSON: a list of lists of ids.

Bounds, each checked before what it bounds is built and refused with the file and the line:
:data:`MAX_LOOKS_BYTES` per file (read at most), :data:`MAX_LOOKS` looks, :data:`MAX_LOOK_PARTS`
part ids in all, :data:`MAX_LOOK_LINES` lines and :data:`MAX_LOOK_LINE_CHARS` characters a line (a
text file), or :data:`MAX_LOOKS` + :data:`MAX_LOOK_PARTS` values (a JSON file, counted before it is
parsed).  A part id seen again is the same string: memory grows with the looks, not the bytes.

>>> parse_looks("rl ra\\n-\\nco  # the cover\\n")
[('rl', 'ra'), (), ('co',)]
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from opportune.formats.problems import Problem
from opportune.limits import MAX_LOOK_PARTS, MAX_LOOKS, MAX_LOOKS_BYTES  # noqa: F401 (their home: the one table of limits)


MAX_LOOK_LINES = 2 * MAX_LOOKS  # lines of a text looks file, comments and blank lines included
MAX_LOOK_LINE_CHARS = 200_000   # characters of one line (a look of 10,000 parts of 19 characters)
# What str.splitlines splits on: counted before any line is built.
_LINE_BREAKS = ("\n", "\r", "\x0b", "\x0c", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029")
_SURROGATE = re.compile("[\ud800-\udfff]")


def _shown(value) -> str:
    """A value for a message: cut short, every character that is not printable ASCII escaped."""
    text = ascii(value)
    return text if len(text) <= 60 else text[:57] + "..."


class LooksError(ValueError):
    """A looks file that cannot be used: the problem, with its file, line and what to do.

    Parameters
    ----------
    problem : Problem
        What is wrong (``problem.where``: the file and line).

    Examples
    --------
    >>> try:
    ...     parse_looks('[["a"', file="cell.looks")
    ... except LooksError as error:
    ...     print(error.problem.where)
    cell.looks:1
    """
    def __init__(self, problem: Problem):
        self.problem = problem
        super().__init__(str(problem))


def _over(what: str, limit: int, hint: str, file: str | None, line: int | None) -> LooksError:
    return LooksError(Problem(f"more than {limit:,} {what}; looks files of at most {limit:,} are read", hint,
                              file=file, line=line, code="limit"))


def parse_looks(text: str, *, file: str | None = None) -> list[tuple[str, ...]]:
    """Parse a looks file's text (text or JSON form).

    O(len(text)); bounded as the module says, before the looks are built.

    Parameters
    ----------
    text : str
        Text: part ids separated by spaces or commas, one look per line, ``-`` for an empty look,
        ``#`` starting a comment.  JSON: a list of lists of ids.
    file : str, optional
        The name problems are reported under.

    Returns
    -------
    list of tuple of str
        The looks, in order.

    Raises
    ------
    LooksError
        With the file and line of the first problem: malformed JSON, a value that is not a part id,
        or a bound passed.

    Examples
    --------
    >>> parse_looks('[["rl", "ra"], []]')
    [('rl', 'ra'), ()]
    >>> parse_looks("[1]", file="x.looks")
    Traceback (most recent call last):
        ...
    opportune.formats.looks.LooksError: x.looks: error: a JSON looks file must be a list of lists of part ids — e.g. [["rl", "ra"], []]
    """
    stripped = text.lstrip()
    if stripped.startswith("["):
        from opportune.formats.documents import json_values_past

        past = json_values_past(text, 1 + MAX_LOOKS + MAX_LOOK_PARTS)
        if past is not None:
            raise _over("values (looks and part ids)", 1 + MAX_LOOKS + MAX_LOOK_PARTS,
                        "split the looks into several files", file, past)
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise LooksError(Problem(f"JSON syntax error: {exc.msg}", "a JSON looks file is a list of lists of part ids",
                                     file=file, line=exc.lineno, code="syntax")) from None
        except (RecursionError, ValueError) as exc:  # nested too deep for the parser; an integer of 4,300+ digits
            what = "values nested too deep" if isinstance(exc, RecursionError) else str(exc.args[0] if exc.args else exc)
            raise LooksError(Problem(f"cannot read the JSON: {what}", 'a JSON looks file is a list of lists of part ids, '
                                     'e.g. [["rl", "ra"], []]', file=file, code="syntax")) from None
        if not isinstance(data, list) or not all(isinstance(look, list) for look in data):
            raise LooksError(Problem("a JSON looks file must be a list of lists of part ids", 'e.g. [["rl", "ra"], []]',
                                     file=file, code="type"))
        for i, look in enumerate(data):
            for part in look:
                if not isinstance(part, (str, int)) or isinstance(part, bool):
                    raise LooksError(Problem(f"look {i + 1}: {_shown(part)} is not a part id", "use strings",
                                             file=file, code="type"))
                if isinstance(part, str) and _SURROGATE.search(part):
                    raise LooksError(Problem(f"look {i + 1}: {_shown(part)} is not valid Unicode text (half of a "
                                             "surrogate pair)", "write part ids as they are in the plan",
                                             file=file, code="text"))
        if len(data) > MAX_LOOKS:
            raise _over("looks", MAX_LOOKS, "split the looks into several files", file, None)
        same: dict[str, str] = {}
        return [tuple(same.setdefault(p, p) for p in map(str, look)) for look in data]
    lines = sum(text.count(c) for c in _LINE_BREAKS) - text.count("\r\n")
    if lines > MAX_LOOK_LINES:
        raise _over("lines", MAX_LOOK_LINES, "split the looks into several files", file, MAX_LOOK_LINES + 1)
    looks = []
    same = {}  # each id once in memory, however often it is seen
    total = 0
    for no, line in enumerate(text.splitlines(), start=1):
        if len(line) > MAX_LOOK_LINE_CHARS:
            raise LooksError(Problem(f"a line of {len(line):,} characters; lines of at most {MAX_LOOK_LINE_CHARS:,} "
                                     "are read", "one look per line", file=file, line=no, code="limit"))
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        if len(looks) >= MAX_LOOKS:
            raise _over("looks", MAX_LOOKS, "split the looks into several files", file, no)
        if line == "-":
            looks.append(())
            continue
        parts = tuple(same.setdefault(p, p) for p in line.replace(",", " ").split())
        if "-" in parts:
            raise LooksError(Problem("'-' (an empty look) must stand alone on its line",
                                     "write '-' alone, or list the visible parts", file=file, line=no, code="syntax"))
        total += len(parts)
        if total > MAX_LOOK_PARTS:
            raise _over("part ids in all", MAX_LOOK_PARTS, "split the looks into several files", file, no)
        looks.append(parts)
    return looks


def read_looks(path: str | Path) -> list[tuple[str, ...]]:
    """Read a looks file, or ``example:NAME`` (a shipped one).

    At most :data:`MAX_LOOKS_BYTES` bytes are read.

    Parameters
    ----------
    path : str or os.PathLike
        The file, or ``example:NAME``.

    Returns
    -------
    list of tuple of str
        The looks, in order.

    Raises
    ------
    LooksError
        If the file cannot be read (missing included) or holds a problem, as :func:`parse_looks`.

    Examples
    --------
    >>> read_looks("example:gearbox-table1")[:2]
    [('rl', 'ra'), ('ca', 'co')]
    >>> read_looks("no-such.looks")
    Traceback (most recent call last):
        ...
    opportune.formats.looks.LooksError: error: no such file: no-such.looks — check the path
    """
    if str(path).lower().startswith("example:"):
        from opportune.formats import shipped

        try:
            path = shipped.example_path(str(path)[len("example:"):])
        except KeyError as exc:
            raise LooksError(Problem(str(exc.args[0]), "use one of these names, e.g. example:gearbox-table1",
                                     code="io")) from None
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_LOOKS_BYTES + 1)
        if len(raw) > MAX_LOOKS_BYTES:
            raise LooksError(Problem(f"{path} is larger than {MAX_LOOKS_BYTES:,} bytes; looks files of at most "
                                     f"{MAX_LOOKS_BYTES:,} bytes are read", "split the looks into several files",
                                     file=str(path), code="limit"))
        text = raw.decode("utf-8")
    except FileNotFoundError:
        raise LooksError(Problem(f"no such file: {path}", "check the path", code="io")) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LooksError(Problem(f"cannot read {path}: {exc}", "give a UTF-8 text file", code="io")) from None
    return parse_looks(text, file=str(path))
