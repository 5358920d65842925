"""What every plan reader shares: a parsed document with its lines, the outcome of a check, the bounds
on a file and its values, a file's format and name, and JSON's value count before parsing.

The readers (:mod:`~opportune.formats.loader` and the graph formats) import these; the loader's entry
points (:func:`~opportune.formats.loader.read_plan`, :func:`~opportune.formats.loader.load_plan`) choose
the reader, so nothing here imports a reader.
"""

from __future__ import annotations

import itertools
import os
import re
from dataclasses import dataclass, field

from opportune.formats.problems import Problem
from opportune.limits import MAX_ALIAS_VALUES, MAX_ALIASES, MAX_DEPTH, MAX_FILE_BYTES, MAX_VALUES  # noqa: F401 (their home: the one table of limits)

# not typing.TYPE_CHECKING: importing typing (and pathlib) costs 10 ms of a count's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from pathlib import Path
    from typing import Any, Callable

    from opportune.planning.plan import Plan


YAML_SUFFIXES = {".yaml", ".yml"}
JSON_SUFFIXES = {".json"}
IN2_SUFFIXES = {".in2"}


@dataclass
class Document:
    """A parsed plan document with the line of every value (JSON-pointer-like paths)."""

    data: Any
    lines: dict[tuple, int] = field(default_factory=dict)
    file: str | None = None
    problems: list[Problem] = field(default_factory=list)
    # Finds the lines when one is first asked for (a JSON plan's lines cost a second, YAML, pass:
    # a plan without problems never needs them).
    locate: Callable[[], dict[tuple, int]] | None = field(default=None, repr=False, compare=False)

    def line(self, path: tuple) -> int | None:
        """Line of ``path``, or of its nearest ancestor that has one."""
        if self.locate is not None:
            locate, self.locate = self.locate, None
            self.lines.update(locate())
        while True:
            if path in self.lines:
                return self.lines[path]
            if not path:
                return None
            path = path[:-1]


@dataclass
class CheckResult:
    """Outcome of reading and checking a plan: the plan (if usable) and every finding.

    ``errors`` and ``warnings`` split the problems by severity; ``ok`` says whether the plan can be
    used (a plan and no error).

    Parameters
    ----------
    plan : Plan or None
        The plan, or ``None`` if it is not usable.
    problems : list of Problem
        Every problem found, errors and warnings.

    Examples
    --------
    >>> from opportune.formats.loader import check_text
    >>> result = check_text('{"parts": ["a", "a"]}', fmt="json", file="twice.json")
    >>> result.ok, len(result.errors), result.errors[0].where
    (False, 1, 'twice.json:1')
    """

    plan: Plan | None
    problems: list[Problem]

    @property
    def errors(self) -> list[Problem]:
        return [p for p in self.problems if p.severity == "error"]

    @property
    def warnings(self) -> list[Problem]:
        return [p for p in self.problems if p.severity == "warning"]

    @property
    def ok(self) -> bool:
        return self.plan is not None and not self.errors


def file_suffix(path: str | Path) -> str:
    """The suffix of the file name, lower case (``".yaml"``; ``""`` for none), as ``Path.suffix`` gives it."""
    name = os.path.basename(os.path.normpath(os.fspath(path)))
    i = name.rfind(".")
    return name[i:].lower() if 0 < i < len(name) - 1 else ""


def detect_format(path: str | Path, text: str | None = None) -> str:
    """``"yaml"``, ``"json"`` or ``"in2"`` from the suffix, else from the content."""
    suffix = file_suffix(path)
    if suffix in YAML_SUFFIXES:
        return "yaml"
    if suffix in JSON_SUFFIXES:
        return "json"
    if suffix in IN2_SUFFIXES:
        return "in2"
    if text is not None:
        head = text.lstrip()[:1]
        if head in "[{":
            return "json"
        first = text.strip().splitlines()[0].strip() if text.strip() else ""
        if first.isdigit():
            return "in2"
    return "yaml"


def file_stem(file: str) -> str:
    """A plan's default name from its file's label: the file name without its suffix, and a shipped file
    named ``salbp:TONGE70`` or ``example:gearbox`` by its own name (``TONGE70``).

    >>> file_stem("/data/TONGE70.IN2"), file_stem("salbp:TONGE70"), file_stem("graph")
    ('TONGE70', 'TONGE70', 'graph')
    """
    tail = file.replace("\\", "/").rsplit("/", 1)[-1]
    if tail.lower().startswith(("salbp:", "example:")):
        return tail.split(":", 1)[1]
    return tail.rsplit(".", 1)[0] if "." in tail.lstrip(".") else tail


def not_utf8(raw: bytes, exc: UnicodeDecodeError, file: str | None) -> Problem:
    """The problem of bytes that are not UTF-8: the line, the column and the bytes, described (never printed raw)."""
    start = exc.start
    line_start = raw.rfind(b"\n", 0, start) + 1
    bad = raw[start: max(exc.end, start + 1)][:4]
    shown = " ".join(f"0x{b:02x}" for b in bad)
    return Problem(f"the file is not valid UTF-8 text: byte{'s' if len(bad) > 1 else ''} {shown} at column "
                   f"{start - line_start + 1}", "save the file as UTF-8 (an editor's 'save with encoding')",
                   file=file, line=raw.count(b"\n", 0, start) + 1, code="syntax")


# A JSON string literal (no raw line break can stand in one), or an escape outside any: removed
# before the separators are counted.  The escape alternative keeps the scan linear on a line of
# unterminated quotes; the possessive repeats keep the matcher's memory constant (a plain repeat
# of a group saves its state at every step: 1.2 GB for a string of ten million escapes).
_JSON_STRING = re.compile(r'"(?>[^"\\\n]++|\\.)*+"|\\.')
_JSON_SEPARATOR = re.compile(r"[,:\[{]")
_SPACE = re.compile(r"\s*")


def json_values_past(text: str, limit: int) -> int | None:
    """The line of the first value past ``limit`` in JSON ``text``, or None if it has at most ``limit``.

    A document's values are 1 + its commas + its colons (keys) + its non-empty lists and objects,
    counted outside string literals: one regular-expression pass and four ``str.count`` (C speed,
    O(len(text)), memory one copy of the text), before anything is parsed.  An empty list or
    object counts one value more than it has: the count is an upper bound, exact for plans.

    >>> json_values_past('[1, 2, "3,4"]', 4), json_values_past('[1,\\n 2, 3]', 3)
    (None, 2)
    """
    if 1 + sum(text.count(c) for c in ",:[{") <= limit:
        return None  # even with the separators inside strings counted
    bare = _JSON_STRING.sub('""', text)
    if 1 + sum(bare.count(c) for c in ",:[{") <= limit:
        return None
    past = next(itertools.islice(_JSON_SEPARATOR.finditer(bare), limit - 1, None), None)
    if past is None:
        return 1
    start = _SPACE.match(bare, past.end()).end()  # where the value after the separator starts
    return bare.count("\n", 0, start) + 1
