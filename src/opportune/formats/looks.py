"""Looks files: what the vision system saw, one look per line.

Text: part ids separated by spaces or commas, ``-`` for an empty look,
``#`` starts a comment, blank lines are skipped.  JSON: a list of lists of ids.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from opportune.formats.problems import Problem


MAX_LOOKS_BYTES = 32 << 20  # a looks file (32 MiB)
_SURROGATE = re.compile("[\ud800-\udfff]")


def _shown(value) -> str:
    """A value for a message: cut short, every character that is not printable ASCII escaped."""
    text = ascii(value)
    return text if len(text) <= 60 else text[:57] + "..."


class LooksError(ValueError):
    def __init__(self, problem: Problem):
        self.problem = problem
        super().__init__(str(problem))


def parse_looks(text: str, *, file: str | None = None) -> list[tuple[str, ...]]:
    """Parse a looks file's text (text or JSON form); raise :class:`LooksError` with the line."""
    stripped = text.lstrip()
    if stripped.startswith("["):
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
        return [tuple(str(p) for p in look) for look in data]
    looks = []
    for no, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        if line == "-":
            looks.append(())
            continue
        parts = tuple(p for p in line.replace(",", " ").split() if p)
        if "-" in parts:
            raise LooksError(Problem("'-' (an empty look) must stand alone on its line",
                                     "write '-' alone, or list the visible parts", file=file, line=no, code="syntax"))
        looks.append(parts)
    return looks


def read_looks(path: str | Path) -> list[tuple[str, ...]]:
    """Read a looks file (or ``example:NAME``, a shipped one); raise :class:`LooksError` (missing file included)."""
    if str(path).lower().startswith("example:"):
        from opportune import datasets

        try:
            path = datasets.example_path(str(path)[len("example:"):])
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
