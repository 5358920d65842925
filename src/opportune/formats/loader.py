"""Reading plan files: YAML, JSON (one schema) and SALBP ``.IN2`` precedence graphs.

Every reader returns a :class:`~opportune.planning.plan.Plan` or raises
:class:`~opportune.planning.plan.PlanError` carrying *every* problem found, each with
its file, line and what to do.  YAML is read with PyYAML's safe loader only:
no tag in a plan file can run code.

Every size is bounded before it can cost time or memory, and each refusal
states its limit, the file and the line: a file holds at most
:data:`MAX_FILE_BYTES` (checked before it is read: at most one byte more is
read); a document holds at most :data:`MAX_VALUES` values (scalars, lists and
mappings, keys included) — counted by a pre-scan that builds nothing for JSON
(string literals removed and separators counted), and for YAML while its
values are built from libyaml's events in one pass that stops at the first
bound passed, so a document of millions of values is refused in well under a
second and a few times its size in memory; values nest at most
:data:`MAX_DEPTH` deep (checked by the same passes); a YAML file uses at most
:data:`MAX_ALIASES` aliases,
none of them inside the value it names, and its aliases add at most
:data:`MAX_ALIAS_VALUES` values by repeating what they name (an "alias bomb"
of a few hundred bytes would otherwise expand to billions); a string holds at
most :data:`~opportune.formats.validate.MAX_TEXT` characters.  The limits on
plans themselves (parts, units, strategies, constraints) are in
:mod:`opportune.planning.plan`; :data:`MAX_VALUES` keeps every document the loaders
accept (10,000 parts and about 130,000 constraints at most) loaded within
5 s of CPU time and 500 MB (``benchmarks/bench_loaders.py`` measures every
bound's corner).  A JSON plan's lines are found only when a problem needs one,
by one pass over its tokens (:func:`json_lines`).

>>> check_text('parts: [' + ', '.join(['a'] * (MAX_VALUES + 1)) + ']', file='big.yaml').errors[0].where
'big.yaml:1'
"""

from __future__ import annotations

import os
import re
from functools import partial

from opportune.formats.documents import (IN2_SUFFIXES, JSON_SUFFIXES, MAX_ALIAS_VALUES, MAX_ALIASES, MAX_DEPTH,  # noqa: F401
                                         MAX_FILE_BYTES, MAX_VALUES, YAML_SUFFIXES, CheckResult, Document, file_suffix,
                                         detect_format, file_stem, json_values_past, not_utf8)
from opportune.formats.problems import Problem
from opportune.planning.plan import Part, Plan, PlanError, geometry_dict

# not typing.TYPE_CHECKING: importing typing (and pathlib) costs 10 ms of a count's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping
    from pathlib import Path
    from typing import Any


def read_plan(path: str | Path, *, allow_cycles: bool = False) -> CheckResult:
    """Read and check a plan file of any supported format; never raises for bad content.

    ``salbp:NAME`` reads a SALBP graph shipped with the package, ``example:NAME`` an example
    (:mod:`opportune.datasets`), and ``-`` standard input.  The format is found from the suffix, else
    from the content.  At most :data:`MAX_FILE_BYTES` bytes are read.

    Parameters
    ----------
    path : str or os.PathLike
        The file, ``salbp:NAME``, ``example:NAME`` or ``-``.
    allow_cycles : bool, default False
        Keep the cyclic strategies of a YAML or JSON plan instead of refusing it (for
        ``opportune relax`` only).

    Returns
    -------
    CheckResult
        The plan (``None`` if unusable) and every problem found, each with its file, line and what
        to do; ``result.ok`` says whether the plan can be used.

    See Also
    --------
    load_plan : the same, raising :class:`PlanError` instead of returning problems.

    Examples
    --------
    >>> read_plan("example:gearbox").plan.part_ids[:4]
    ('ca', 'ba', 'rl', 'dr')
    >>> result = read_plan("no-such-plan.yaml")
    >>> result.ok, result.errors[0].message
    (False, 'no such file: no-such-plan.yaml')
    """
    shipped = None      # a shipped file is named by its short name in messages, not its installed path
    if str(path).lower().startswith(("salbp:", "example:")):
        from opportune.formats.shipped import resolve

        try:
            shipped = str(path)
            path = resolve(path)
        except KeyError as exc:
            example = "salbp:KILBRID" if str(path).lower().startswith("salbp:") else "example:gearbox"
            return CheckResult(None, [Problem(str(exc.args[0]), f"use one of these names, e.g. {example}",
                                              code="io")])
    stdin = str(path) == "-"
    path = "<stdin>" if stdin else os.fspath(path)
    name = shipped or str(path)
    try:
        if stdin:       # `-`: the plan on standard input (YAML or JSON by its content, .IN2 or .alb by its shape)
            import sys

            raw = sys.stdin.buffer.read(MAX_FILE_BYTES + 1)
        else:
            with open(path, "rb") as f:  # read at most the limit (and one byte more, to know): /dev/zero is a file too
                raw = f.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            return CheckResult(None, [_too_large(name)])
    except FileNotFoundError:
        return CheckResult(None, [Problem(f"no such file: {name}", "check the path", code="io")])
    except IsADirectoryError:
        return CheckResult(None, [Problem(f"{name} is a directory, not a plan file", "give a .yaml, .json or .IN2 file", code="io")])
    except OSError as exc:
        return CheckResult(None, [Problem(f"cannot read {name}: {exc.strerror}", "check the file's permissions", code="io")])
    suffix = file_suffix(path)
    if suffix == ".alb" or b"<" in raw[:200]:   # .alb's first line is `<number of tasks>`: else no need to load it
        from opportune.formats.alb import check_alb_bytes, is_alb

        if is_alb(path, raw):
            return check_alb_bytes(raw, file=name)
    head = raw[:400].lstrip()
    if suffix == ".graphml" or (suffix not in YAML_SUFFIXES | JSON_SUFFIXES and head.startswith(b"<")):
        from opportune.formats.graphfiles import check_graphml_bytes

        return check_graphml_bytes(raw, file=name)
    if suffix in (".dot", ".gv") or re.match(rb"(?:strict\s+)?digraph\b", head):
        from opportune.formats.graphfiles import check_dot_bytes

        return check_dot_bytes(raw, file=name)
    fmt = detect_format(path, raw[:200].decode("latin-1"))
    if fmt == "in2":
        from opportune.formats.salbp import check_in2_bytes

        return check_in2_bytes(raw, file=name)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        return CheckResult(None, [not_utf8(raw, exc, name)])
    return check_text(text, fmt=fmt, file=name, allow_cycles=allow_cycles)


def load_plan(path: str | Path) -> Plan:
    """Load a plan file (YAML, JSON, SALBP ``.IN2`` or ``.alb``, GraphML, DOT).

    Parameters
    ----------
    path : str or os.PathLike
        The file, ``salbp:NAME`` or ``example:NAME`` for the data shipped with the package
        (:mod:`opportune.datasets`), or ``-`` for standard input.

    Returns
    -------
    Plan
        The checked plan.

    Raises
    ------
    PlanError
        If the file cannot be read or holds any error; it lists every problem found, each with
        its file, line and what to do.

    See Also
    --------
    read_plan : the same, returning the problems (warnings included) instead of raising.
    make_plan : a plan from Python values.

    Examples
    --------
    >>> plan = load_plan("example:gearbox")
    >>> plan.name, len(plan.part_ids)
    ('gearbox', 10)
    >>> load_plan("no-such-plan.yaml")
    Traceback (most recent call last):
        ...
    opportune.planning.plan.PlanError: error: no such file: no-such-plan.yaml — check the path
    """
    result = read_plan(path)
    if not result.ok:
        raise PlanError(result.errors)
    return result.plan


def _too_large(name: str) -> Problem:
    return Problem(f"{name} is larger than {MAX_FILE_BYTES:,} bytes; plan files of at most {MAX_FILE_BYTES:,} bytes "
                   "are read", "split the plan into smaller ones", file=name, code="limit")


def check_text(text: str, *, fmt: str = "yaml", file: str | None = None, allow_cycles: bool = False) -> CheckResult:
    """Parse and check plan text, as :func:`read_plan` checks a file.

    Parameters
    ----------
    text : str
        The plan, in the file schema (docs/plan-files.md).
    fmt : {"yaml", "json"}, default "yaml"
        The text's format.
    file : str, optional
        The name problems are reported under (``None``: no file name).
    allow_cycles : bool, default False
        As in :func:`read_plan`.

    Returns
    -------
    CheckResult
        The plan (``None`` if unusable) and every problem found.  Text of more than
        :data:`MAX_FILE_BYTES` bytes (as UTF-8) is refused as a file of that size is.

    Examples
    --------
    >>> check_text('{"parts": ["a", "b"], "requires": {"b": ["a"]}}', fmt="json").plan.part_ids
    ('a', 'b')
    >>> result = check_text("parts: [a, a]", file="twice.yaml")
    >>> result.ok, result.errors[0].where
    (False, 'twice.yaml:1')
    """
    if len(text) > MAX_FILE_BYTES // 4 and len(text.encode("utf-8", "surrogatepass")) > MAX_FILE_BYTES:
        return CheckResult(None, [_too_large(file or "the plan")])
    doc = parse_json(text, file) if fmt == "json" else parse_yaml(text, file)
    if doc.problems:
        return CheckResult(None, doc.problems)
    from opportune.formats.validate import check_document

    return check_document(doc, allow_cycles=allow_cycles)


def plan_from_dict(data: Any, *, file: str | None = None) -> Plan:
    """Build a plan from already-parsed data in the file schema (what ``yaml.safe_load`` or
    ``json.load`` returns).

    Parameters
    ----------
    data : dict
        The plan document: ``parts`` and ``requires``, ``strategies`` or ``assemblies``
        (docs/plan-files.md).
    file : str, optional
        The name problems are reported under.

    Returns
    -------
    Plan
        The checked plan.

    Raises
    ------
    PlanError
        If the data holds any error; it lists every problem found.

    Examples
    --------
    >>> plan_from_dict({"parts": ["a", "b"], "requires": {"b": ["a"]}}).part_ids
    ('a', 'b')
    """
    from opportune.formats.validate import check_document

    result = check_document(Document(data, {}, file))
    if not result.ok:
        raise PlanError(result.errors)
    return result.plan


def make_plan(
    parts: Iterable[str | dict | Part],
    requires: Mapping[str, Iterable[str]] | None = None,
    *,
    strategies: Mapping[str, Mapping[str, Iterable[str]]] | None = None,
    name: str = "plan",
) -> Plan:
    """Build and validate a plan from Python values.

    Parameters
    ----------
    parts : iterable of str, dict or Part
        The parts: ids, part mappings of the file schema (``{"id": "a", "quantity": 2}``) or
        :class:`Part` objects.
    requires : mapping of str to iterable of str, optional
        One strategy: each part's prerequisites (part → parts that must be installed first).
    strategies : mapping of str to mapping, optional
        Several strategies instead of ``requires``: name → requires.
    name : str, default "plan"
        The plan's name.

    Returns
    -------
    Plan
        The checked plan.

    Raises
    ------
    PlanError
        Listing every problem, as ``opportune check`` would (unknown parts, cycles, duplicates).

    Examples
    --------
    >>> make_plan(["a", "b"], {"b": ["a"]}).part_ids
    ('a', 'b')
    >>> [s.name for s in make_plan(["a", "b", "c"], strategies={"s1": {"c": ["a"]}, "s2": {"c": ["b"]}}).strategies]
    ['s1', 's2']
    >>> make_plan(["a"], {"b": ["a"]})
    Traceback (most recent call last):
        ...
    opportune.planning.plan.PlanError: error: unknown part 'b' listed with requirements (strategy 'default') — declare it under `parts` or fix the id
    """
    doc: dict = {"name": name, "parts": [p if isinstance(p, (str, dict)) else _part_dict(p) for p in parts]}
    if strategies is not None:
        doc["strategies"] = [{"name": k, "requires": {a: list(b) for a, b in v.items()}} for k, v in strategies.items()]
    else:
        doc["requires"] = {a: list(b) for a, b in (requires or {}).items()}
    return plan_from_dict(doc)


def plan_from_andor(parts: Iterable[str | dict], assemblies: Mapping[str, list[dict]], *, product: str | None = None,
                    name: str = "plan") -> Plan:
    """A plan from an AND/OR graph given as Python values (the file schema's ``assemblies``).

    Checked and expanded exactly as a file would be (docs/andor.md).

    Parameters
    ----------
    parts : iterable of str or dict
        The parts, as in :func:`make_plan`.
    assemblies : mapping of str to list of dict
        Each assembly's ways of being made: ``{"join": [...], "then": [...]}`` mappings.
    product : str, optional
        The product (``None``: the first assembly listed).
    name : str, default "plan"
        The plan's name.

    Returns
    -------
    Plan
        One strategy per way of making the product.

    Raises
    ------
    PlanError
        With every problem found.

    Examples
    --------
    >>> plan = plan_from_andor(["a", "b", "c"], {"p": [{"join": ["a", "b"], "then": ["c"]}]})
    >>> plan.strategies[0].pairs()
    [('a', 'c'), ('b', 'c')]
    """
    doc: dict[str, Any] = {"name": name, "parts": list(parts), "assemblies": dict(assemblies)}
    if product is not None:
        doc["product"] = product
    return plan_from_dict(doc)


def _part_dict(p: Part) -> dict:
    d = {"id": p.id, "name": p.name, "quantity": p.quantity, "acquire": p.acquire, "install": p.install,
         "visibility": p.visibility, "geometry": None if p.geometry is None else geometry_dict(p.geometry)}
    return {k: v for k, v in d.items() if v is not None}


# ---------------------------------------------------------------- parsing


class _Refused(Exception):
    """A document over one of the loader's limits: the problem to report."""

    def __init__(self, message: str, hint: str, line: int | None):
        super().__init__(message)
        self.message, self.hint, self.line = message, hint, line


_DEPTH_HINT = "a plan nests at most 6 levels (strategies, requires, lists): remove the extra brackets or indentation"
_STR_TAG = "tag:yaml.org,2002:str"


def _too_many_values() -> tuple[str, str]:
    """The message and hint of a document over :data:`MAX_VALUES` (the line is the caller's)."""
    message = (f"the document has more than {MAX_VALUES:,} values (list items, mapping keys and values); "
               f"at most {MAX_VALUES:,} are read")
    return message, ("split the plan into smaller ones: a plan holds at most 10,000 parts, and a few "
                     "constraints per part are usual")


# YAML starts a value only at the start of a line or after one of these: their count bounds the
# values of a document from above, in a few passes of str.count (C speed, nothing built).  Used
# without libyaml, where an event pass costs ten times as much.
_YAML_SEPARATORS = ("\n", "\r", "\x85", "\u2028", "\u2029", ",", "-", ":", "?", "[", "{")


def _prescan_yaml(text: str) -> int | None:
    """Refuse YAML text of more than :data:`MAX_VALUES` values, :data:`MAX_DEPTH` levels or
    :data:`MAX_ALIASES` aliases before any node is composed; the number of aliases, or None if not scanned.

    With libyaml, one pass over the parser's events (cheap: each dropped once counted, so
    memory stays that of the text) that stops at the first bound passed; the text is then safe for
    libyaml's own composer, twice as fast as PyYAML's (which has no bound of its own: a list nested
    200,000 deep would overflow its C stack).  Without libyaml, only an upper bound from
    :data:`_YAML_SEPARATORS` (O(len(text)), no allocation), the events counted only when it is over
    the limit, and None: the composer in Python keeps the bounds itself.  Raises :class:`_Refused`
    with the line of the first value past a bound; a syntax error met on the way is raised as
    PyYAML's (the caller reports it with its line).
    """
    import yaml

    libyaml = getattr(yaml, "__with_libyaml__", False)
    if not libyaml and 1 + sum(text.count(c) for c in _YAML_SEPARATORS) <= MAX_VALUES:
        return None
    parser = (yaml.CSafeLoader if libyaml else yaml.SafeLoader)(text)
    opening, closing = (yaml.SequenceStartEvent, yaml.MappingStartEvent), (yaml.SequenceEndEvent, yaml.MappingEndEvent)
    values = depth = aliases = 0
    try:
        while parser.check_event():
            event = parser.get_event()
            if isinstance(event, closing):
                depth -= 1
                continue
            if isinstance(event, yaml.AliasEvent):
                aliases += 1
                if aliases > MAX_ALIASES:
                    raise _Refused(f"more than {MAX_ALIASES:,} YAML aliases (*name)",
                                   "write the values out instead of repeating them with aliases",
                                   event.start_mark.line + 1)
            elif not isinstance(event, (yaml.ScalarEvent, *opening)):
                continue  # stream and document events
            values += 1
            if values > MAX_VALUES:
                raise _Refused(*_too_many_values(), event.start_mark.line + 1)
            if depth + 1 > MAX_DEPTH and not isinstance(event, yaml.AliasEvent):
                raise _Refused(f"values nested more than {MAX_DEPTH} levels deep", _DEPTH_HINT,
                               event.start_mark.line + 1)
            if isinstance(event, opening):
                depth += 1
    finally:
        parser.dispose()
    return aliases if libyaml else None


def _prescan_json(text: str) -> None:
    """Refuse JSON text of more than :data:`MAX_VALUES` values before it is parsed (:func:`json_values_past`)."""
    line = json_values_past(text, MAX_VALUES)
    if line is not None:
        raise _Refused(*_too_many_values(), line)
_loader_class = None


def _bounded_loader():
    """PyYAML's safe loader, composing at most :data:`MAX_DEPTH` levels and :data:`MAX_ALIASES` aliases.

    Events come from libyaml's C parser when PyYAML has it (about ten times faster than the pure
    Python one), else from the pure Python parser; they are composed into nodes here, in Python, so
    that the bounds hold (the composer is recursive: bounding its depth keeps it far from Python's
    recursion limit).
    """
    global _loader_class
    if _loader_class is None:
        import yaml
        from yaml.composer import Composer
        from yaml.constructor import SafeConstructor
        from yaml.resolver import Resolver

        class BoundedComposer(Composer):
            def __init__(self):
                super().__init__()
                self._depth = 0
                self._aliases = 0
                self._values = 0  # nodes composed (a backstop: the pre-scan has counted them already)

            def compose_node(self, parent, index):
                if self.check_event(yaml.AliasEvent):
                    self._aliases += 1
                    if self._aliases > MAX_ALIASES:
                        raise _Refused(f"more than {MAX_ALIASES:,} YAML aliases (*name)",
                                       "write the values out instead of repeating them with aliases",
                                       self.peek_event().start_mark.line + 1)
                    return super().compose_node(parent, index)
                self._depth += 1
                self._values += 1
                try:
                    if self._values > MAX_VALUES:
                        raise _Refused(*_too_many_values(), self.peek_event().start_mark.line + 1)
                    if self._depth > MAX_DEPTH:
                        raise _Refused(f"values nested more than {MAX_DEPTH} levels deep", _DEPTH_HINT,
                                       self.peek_event().start_mark.line + 1)
                    return super().compose_node(parent, index)
                finally:
                    self._depth -= 1

        if getattr(yaml, "__with_libyaml__", False):
            from yaml._yaml import CParser

            class BoundedLoader(BoundedComposer, CParser, SafeConstructor, Resolver):
                def __init__(self, stream):
                    CParser.__init__(self, stream)
                    SafeConstructor.__init__(self)
                    Resolver.__init__(self)
                    BoundedComposer.__init__(self)
        else:
            from yaml.parser import Parser
            from yaml.reader import Reader
            from yaml.scanner import Scanner

            class BoundedLoader(BoundedComposer, Reader, Scanner, Parser, SafeConstructor, Resolver):
                def __init__(self, stream):
                    Reader.__init__(self, stream)
                    Scanner.__init__(self)
                    Parser.__init__(self)
                    SafeConstructor.__init__(self)
                    Resolver.__init__(self)
                    BoundedComposer.__init__(self)

        _loader_class = BoundedLoader
    return _loader_class


# The plain YAML that :func:`_plain_yaml` reads: a key, a word (a part id), an integer, a decimal, and a
# phrase (a name or a description: words, spaces and a few punctuation marks, starting with a letter).
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-/]*\Z")
_INT = re.compile(r"-?(?:0|[1-9][0-9]{0,17})\Z")
_DECIMAL = re.compile(r"-?[0-9]{1,15}\.[0-9]{1,15}\Z")
_NUMBER = re.compile(r"-[0-9]")
_PHRASE = re.compile(r"[A-Za-z][A-Za-z0-9_.,()&/\- ]*[A-Za-z0-9_.)]\Z")
# words PyYAML reads as booleans or null in any case: such a document takes the full path
_SPECIAL = {"yes", "no", "true", "false", "on", "off", "null", "y", "n"}
PLAIN_MAX_CHARS = 65_536     # larger documents take the full path (its C parser is as quick there)
PLAIN_MAX_DEPTH = 8
_NOT = object()     # a scalar the plain path does not read


def _plain_scalar(text: str, phrase: bool):
    """A plain scalar as PyYAML's safe loader resolves it, or _NOT when it might resolve otherwise."""
    if _KEY.match(text):
        return _NOT if text.lower() in _SPECIAL else text
    if _INT.match(text):
        return int(text)
    if _DECIMAL.match(text):
        return float(text)
    if phrase and _PHRASE.match(text) and "  " not in text and text.split(" ", 1)[0].lower() not in _SPECIAL:
        return text
    return _NOT


def _plain_yaml(text: str) -> tuple[dict, dict[tuple, int]] | None:
    """The data and each value's line of a small YAML document in the plainest block style (what
    :func:`parse_yaml` gives for it), or None for anything else, which then takes the full path.

    Read: block mappings of plain keys, block sequences of scalars, one-line flow sequences of words
    and numbers (``[a, b, c]``), plain words, integers, decimals and phrases, comments.  Anything
    else, or anything that might read otherwise (quotes, tags, anchors, multi-line scalars, flow
    mappings, booleans and nulls, repeated keys, tabs, several documents), is None: this path only
    saves PyYAML's import on the plans most often counted (docs/bounds.md gives what it costs); the tests compare it with PyYAML's
    on generated and mutated documents.  O(len(text)), at most :data:`PLAIN_MAX_CHARS` characters.

    >>> _plain_yaml("name: six\\nparts: [a, b]\\nrequires:\\n  b: [a]\\n")
    ({'name': 'six', 'parts': ['a', 'b'], 'requires': {'b': ['a']}}, {(): 1, ('name',): 1, ('parts',): 2, ('parts', 0): 2, ('parts', 1): 2, ('requires',): 3, ('requires', 'b'): 4, ('requires', 'b', 0): 4})
    """
    if len(text) > PLAIN_MAX_CHARS or "\t" in text or "\r" in text:
        return None
    rows = []       # (line number, indent, content) of the lines that hold something
    for number, line in enumerate(text.split("\n"), 1):
        content = line.strip(" ")
        if not content or content.startswith("#"):
            continue
        cut = content.find(" #")
        if cut >= 0:
            content = content[:cut].rstrip(" ")
        if "#" in content or content.startswith(("---", "...")):
            return None
        rows.append((number, len(line) - len(line.lstrip(" ")), content))
    if not rows or rows[0][2].startswith("-"):
        return None
    lines: dict[tuple, int] = {}
    at = 0

    def inline(content: str, path: tuple, number: int):
        if content.startswith("["):
            if not content.endswith("]"):
                raise ValueError
            inner = content[1:-1].strip(" ")
            items = [] if not inner else [item.strip(" ") for item in inner.split(",")]
            out = []
            for i, item in enumerate(items):
                value = _plain_scalar(item, False)
                if value is _NOT:
                    raise ValueError
                lines[path + (i,)] = number
                out.append(value)
            return out
        if ": " in content or content.endswith(":") or content.startswith("-") and not _NUMBER.match(content):
            raise ValueError
        value = _plain_scalar(content, True)
        if value is _NOT:
            raise ValueError
        return value

    def block(path: tuple, indent: int, depth: int):
        nonlocal at
        if depth > PLAIN_MAX_DEPTH:
            raise ValueError
        number, _, content = rows[at]
        if content == "-" or content.startswith("- "):        # a block sequence
            out = []
            while at < len(rows) and rows[at][1] == indent and (rows[at][2] == "-" or rows[at][2].startswith("- ")):
                number, _, content = rows[at]
                item = content[1:].strip(" ")
                if not item:
                    raise ValueError
                lines[path + (len(out),)] = number
                out.append(inline(item, path + (len(out),), number))
                at += 1
            return out
        out: dict = {}
        while at < len(rows) and rows[at][1] == indent and not rows[at][2].startswith("-"):
            number, _, content = rows[at]
            key, colon, rest = content.partition(":")
            if not colon or (rest and not rest.startswith(" ")) or not _KEY.match(key) or key.lower() in _SPECIAL \
                    or key in out:
                raise ValueError
            rest = rest.strip(" ")
            at += 1
            lines[path + (key,)] = number
            if rest:
                out[key] = inline(rest, path + (key,), number)
            elif at < len(rows) and (rows[at][1] > indent or rows[at][1] == indent and rows[at][2].startswith("-")):
                out[key] = block(path + (key,), rows[at][1], depth + 1)
            else:
                raise ValueError        # null: the full path
        return out

    try:
        lines[()] = rows[0][0]
        data = block((), rows[0][1], 1)
    except ValueError:
        return None
    if at != len(rows) or len(lines) > MAX_VALUES:
        return None
    return data, lines


def parse_yaml(text: str, file: str | None = None) -> Document:
    """Safe-load YAML keeping each value's line; duplicate keys are problems (PyYAML would silently keep the last).

    Bounded (see the module's limits): depth, aliases, and the values the document expands to; an
    alias inside the value it names (``parts: &a [a, *a]``) is refused rather than followed forever.
    """
    simple = _plain_yaml(text)
    if simple is not None:      # the common small plan, read without PyYAML's import (a count's start-up)
        return Document(simple[0], simple[1], file)
    import yaml  # here, not at the top: a SALBP graph or `--help` never needs PyYAML

    doc = Document(None, {}, file)

    def refused(exc: _Refused) -> Document:
        doc.problems.append(Problem(exc.message, exc.hint, file=file, line=exc.line, code="limit"))
        return doc

    try:
        if getattr(yaml, "__with_libyaml__", False):
            try:
                return _build_from_events(text, doc, yaml)
            except _Fallback:  # aliases, merge keys, keys that are lists: the composer's path below
                doc = Document(None, {}, file)
        aliases = _prescan_yaml(text)
        loader = (_bounded_loader() if aliases is None else yaml.CSafeLoader)(text)
        try:
            node = loader.get_single_node()
        finally:
            loader.dispose()
        if aliases is None:
            aliases = loader._aliases
    except _Refused as exc:
        return refused(exc)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = exc.problem or exc.context or "invalid YAML"
        if "nesting depth" in what:
            # libyaml's own depth limit (PyYAML >= 6.0.4) can stop the parser before ours: the same refusal
            return refused(_Refused(f"values nested more than {MAX_DEPTH} levels deep", _DEPTH_HINT,
                                    mark.line + 1 if mark else None))
        doc.problems.append(
            Problem(
                f"YAML syntax error: {what}",
                "fix the syntax at this line (indentation, a missing ':' or an unclosed bracket are the usual causes)",
                file=file,
                line=mark.line + 1 if mark else None,
                code="syntax",
            )
        )
        return doc
    except yaml.YAMLError as exc:
        doc.problems.append(Problem(f"YAML error: {exc}", "fix the file's syntax", file=file, code="syntax"))
        return doc
    if node is None:
        doc.problems.append(Problem("the file is empty", "write a plan with at least `parts:`", file=file, line=1, code="empty"))
        return doc
    if aliases:  # without aliases the nodes form a tree, already bounded (values, depth) before it was built
        try:
            _measure(node, yaml)  # before anything is built: aliases could make it huge, or endless
        except _Refused as exc:
            return refused(exc)
    doc.data = _build_nodes(node, doc, yaml)
    return doc


def _build_nodes(node, doc: Document, yaml):
    """The value of a composed YAML document (:func:`parse_yaml`'s path for what the event reader leaves):
    each value's line noted in ``doc.lines``; a duplicate key, a key that is a collection or a value the
    safe constructor refuses is a problem in ``doc.problems`` (the first value kept)."""
    constructor = yaml.SafeLoader("")
    mapping, sequence = yaml.MappingNode, yaml.SequenceNode

    def build(n, path):
        line = n.start_mark.line + 1
        doc.lines[path] = line
        if n.tag == _STR_TAG and n.__class__ is yaml.ScalarNode:
            return n.value  # what the constructor would return, at a fraction of its cost
        if isinstance(n, mapping):
            return build_mapping(n, path)
        if isinstance(n, sequence):
            return [build(item, path + (i,)) for i, item in enumerate(n.value)]
        try:
            return constructor.construct_object(n, deep=True)
        except (yaml.YAMLError, ValueError) as exc:  # ValueError: e.g. an integer of more than 4,300 digits
            message = exc.args[0] if isinstance(exc, ValueError) and exc.args else exc
            doc.problems.append(Problem(f"cannot read value: {message}", "write a plain string or number",
                                        file=doc.file, line=line, code="type"))
            return None

    def build_mapping(n, path):
        out = {}
        for knode, vnode in n.value:
            key = build(knode, path + ("<key>",))
            if isinstance(key, (dict, list)):
                doc.problems.append(
                    Problem("a mapping key must be a plain value", "use a part id or field name as key",
                            file=doc.file, line=knode.start_mark.line + 1, code="type")
                )
                continue
            if key in out:
                doc.problems.append(
                    Problem(
                        f"duplicate key {key!r}",
                        "each key may appear once per mapping: merge the two entries",
                        file=doc.file,
                        line=knode.start_mark.line + 1,
                        parts=(str(key),),
                        code="duplicate-key",
                    )
                )
                continue
            out[key] = build(vnode, path + (key,))
            doc.lines[path + (key,)] = knode.start_mark.line + 1
        return out

    return build(node, ())


class _Fallback(Exception):
    """What only the composer's path of :func:`parse_yaml` reads: an alias, a merge key (``<<``), a
    key that is a list or a mapping, a collection with an explicit tag."""


_SEQ_TAG = "tag:yaml.org,2002:seq"
_MAP_TAG = "tag:yaml.org,2002:map"
_MERGE_TAG = "tag:yaml.org,2002:merge"


def _build_from_events(text: str, doc: Document, yaml) -> Document:
    """Build ``doc`` (data, lines, problems) from libyaml's events in one pass, within the bounds.

    The values and depth are counted on the way, as :func:`_prescan_yaml` counts them (the same
    refusals, on the same lines), so one pass replaces three (the pre-scan, the composer and the
    build), a quarter of their time per value (docs/bounds.md gives the measured costs).  No node
    is made: plain scalars that resolve to strings are taken as they are, others
    built by PyYAML's safe constructor.  Raises :class:`_Fallback` at the first alias, merge key,
    list or mapping key, or tagged collection (the composer's path reads those);
    :class:`_Refused` past a bound; PyYAML's errors for bad syntax.
    """
    loader = yaml.CSafeLoader(text)
    try:
        root, documents = _read_events(loader, doc, yaml)
    except (_Refused, yaml.YAMLError):
        doc.lines.clear()  # a refused or broken document is only that problem, as when the pre-scan finds it
        doc.problems.clear()
        raise
    finally:
        loader.dispose()
    if root is None and not documents:
        doc.problems.append(Problem("the file is empty", "write a plan with at least `parts:`", file=doc.file, line=1,
                                code="empty"))
        return doc
    doc.data = root
    return doc

def _read_events(loader, doc: Document, yaml) -> tuple:
    """:func:`_build_from_events`' pass over the events: ``(root value, number of documents)``, with
    ``doc``'s lines and problems filled on the way."""
    constructor = yaml.SafeLoader("")
    resolve = loader.resolve
    scalar_event, alias_event = yaml.ScalarEvent, yaml.AliasEvent
    seq_start, map_start = yaml.SequenceStartEvent, yaml.MappingStartEvent
    ends = (yaml.SequenceEndEvent, yaml.MappingEndEvent)
    doc_start = yaml.DocumentStartEvent
    lines, problems, file = doc.lines, doc.problems, doc.file
    # frames of the open collections: [value, path, is_mapping, key, key_due, key_line, attached]
    stack: list[list] = []
    root = None
    documents = 0
    first_doc_mark = None
    values = 0

    scalar = partial(_event_scalar, resolve, constructor, yaml, problems, file)

    while loader.check_event():
        event = loader.get_event()
        kind = event.__class__
        if kind in ends:
            stack.pop()
            continue
        if kind is alias_event:
            raise _Fallback
        if kind is not scalar_event and kind is not seq_start and kind is not map_start:
            if kind is doc_start:
                documents += 1
                if documents > 1:
                    raise yaml.composer.ComposerError("expected a single document in the stream", first_doc_mark,
                                                      "but found another document", event.start_mark)
                first_doc_mark = event.start_mark
            continue  # stream and document events
        line = event.start_mark.line + 1
        values += 1
        if values > MAX_VALUES:
            raise _Refused(*_too_many_values(), line)
        if len(stack) + 1 > MAX_DEPTH:
            raise _Refused(f"values nested more than {MAX_DEPTH} levels deep", _DEPTH_HINT, line)
        top = stack[-1] if stack else None
        if top is not None and top[2] and top[4]:       # a mapping's key
            if kind is not scalar_event:
                raise _Fallback
            key, tag = scalar(event)
            if tag == _MERGE_TAG:
                raise _Fallback
            top[3], top[4], top[5] = key, False, line
            continue
        if kind is scalar_event:
            value = scalar(event)[0]
        else:
            tag = event.tag
            if tag is not None and tag != "!" and tag != (_SEQ_TAG if kind is seq_start else _MAP_TAG):
                raise _Fallback
            value = [] if kind is seq_start else {}
        attached = True
        if top is None:
            path: tuple = ()
            root = value
            lines[path] = line
        elif top[2]:
            key = top[3]
            top[4] = True
            container = top[0]
            if key in container or not top[6]:
                # a repeated key (PyYAML would keep the last) is a problem; its value is read, not kept
                if top[6]:
                    problems.append(Problem(f"duplicate key {key!r}",
                                            "each key may appear once per mapping: merge the two entries",
                                            file=file, line=top[5], parts=(str(key),), code="duplicate-key"))
                path, attached = (), False
            else:
                path = top[1] + (key,)
                container[key] = value
                lines[path] = top[5]
        else:
            container = top[0]
            path = top[1] + (len(container),)
            if top[6]:
                lines[path] = line
            container.append(value)
            attached = top[6]
        if kind is not scalar_event:
            stack.append([value, path, kind is map_start, None, True, line, attached])
    return root, documents


def _event_scalar(resolve, constructor, yaml, problems: list[Problem], file: str | None, event) -> tuple:
    """A scalar event's ``(value, tag)`` (:func:`_read_events`): a plain string as it is, any other value
    built by PyYAML's safe constructor; a value it refuses is a problem, and None."""
    tag = event.tag
    if tag is None or tag == "!":
        tag = resolve(yaml.ScalarNode, event.value, event.implicit)
    if tag == _STR_TAG:
        return event.value, tag
    node = yaml.ScalarNode(tag, event.value, event.start_mark, event.end_mark, style=event.style)
    try:
        return constructor.construct_object(node, deep=True), tag
    except (yaml.YAMLError, ValueError) as exc:  # ValueError: e.g. an integer of more than 4,300 digits
        message = exc.args[0] if isinstance(exc, ValueError) and exc.args else exc
        problems.append(Problem(f"cannot read value: {message}", "write a plain string or number",
                                file=file, line=event.start_mark.line + 1, code="type"))
        return None, tag


def _measure(root, yaml) -> None:
    """Refuse a composed YAML document whose values, aliases expanded, are endless, too many or too deep.

    Aliases make the composed document a graph that shares nodes; this walks it once (each node's
    expanded size and height memoised), iteratively, so it costs O(nodes composed) however much
    the aliases would expand, and raises :class:`_Refused` with the line of the node at fault.
    """
    size: dict[int, int] = {}
    height: dict[int, int] = {}
    open_: set[int] = set()  # entered, not yet left: the ancestors of the node being entered

    def children(n):
        if isinstance(n, yaml.MappingNode):
            return [x for pair in n.value for x in pair]
        if isinstance(n, yaml.SequenceNode):
            return n.value
        return ()

    stack = [(root, False)]
    while stack:
        n, leaving = stack.pop()
        key = id(n)
        if leaving:
            open_.discard(key)
            kids = children(n)
            size[key] = 1 + sum(size[id(c)] for c in kids)
            height[key] = 1 + max((height[id(c)] for c in kids), default=0)
            line = n.start_mark.line + 1
            if size[key] > MAX_VALUES:
                raise _Refused(f"the document expands to more than {MAX_VALUES:,} values: each alias (*name) repeats "
                               "the whole value it names", "write the values out, or use far fewer aliases", line)
            if height[key] > MAX_DEPTH:
                raise _Refused(f"values nested more than {MAX_DEPTH} levels deep (aliases expanded)", _DEPTH_HINT, line)
            continue
        if key in size:
            continue
        if key in open_:
            raise _Refused("an alias (*name) stands inside the value it names: the value would contain itself "
                           "without end", "use the alias outside the anchored value, or write the values out",
                           n.start_mark.line + 1)
        kids = children(n)
        if not kids:
            size[key], height[key] = 1, 1
            continue
        open_.add(key)
        stack.append((n, True))
        stack.extend((c, False) for c in kids if id(c) not in size)
    added = size[id(root)] - len(size)  # values repeated by aliases
    if added > MAX_ALIAS_VALUES:
        raise _Refused(f"the aliases (*name) of this document repeat {added:,} values; at most {MAX_ALIAS_VALUES:,} "
                       "are accepted", "write the values out, or use far fewer aliases", root.start_mark.line + 1)


_SURROGATE_ESCAPE = re.compile(r"\\u[dD][89a-fA-F][0-9a-fA-F]{2}")


def _too_big(data: Any) -> str | None:
    """Why already-parsed data is over the loader's limits (depth, values), or None.  Iterative, O(values)."""
    values = 0
    stack = [(data, 1)]
    while stack:
        value, depth = stack.pop()
        values += 1
        if values > MAX_VALUES:
            return f"the document has more than {MAX_VALUES:,} values"
        if depth > MAX_DEPTH:
            return f"values nested more than {MAX_DEPTH} levels deep"
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, list):
            stack.extend((v, depth + 1) for v in value)
    return None


# The tokens of valid JSON that :func:`json_lines` needs: strings (possessive, as in _JSON_STRING:
# constant memory on a long one), brackets, and other scalars; commas and colons are skipped.
_JSON_TOKEN = re.compile(r'"(?>[^"\\\n]++|\\.)*+"|[\[\]{}]|[^\s\[\]{},:"]+')


def json_lines(text: str) -> dict[tuple, int]:
    """The line of every value of valid JSON ``text``, by path (a list item's where it starts, a
    mapping value's where its key stands), as :func:`parse_yaml` records them.

    One regular-expression pass over the tokens: O(len(text)), some thirty times cheaper a value
    than the YAML pass it replaces (docs/bounds.md gives the measured costs).  Memory: the
    paths (a few tens of bytes each).

    >>> lines = json_lines('{"parts": ["a",\\n "b"], "requires": {\\n"b": "a"}}')
    >>> lines[("parts", 1)], lines[("requires", "b")]
    (2, 3)
    """
    import json     # here, not at the top: a YAML plan never needs it

    lines: dict[tuple, int] = {}
    # frames of the open containers: [is_mapping, path, next index | current key, a key is due]
    stack: list[list] = []
    line, pos = 1, 0
    count = text.count
    for m in _JSON_TOKEN.finditer(text):
        start = m.start()
        line += count("\n", pos, start)
        pos = start
        tok = m.group()
        c = tok[0]
        if c == "]" or c == "}":
            stack.pop()
        else:
            if not stack:
                path: tuple = ()
                lines[path] = line
            else:
                top = stack[-1]
                if top[0]:
                    if top[3]:      # a key: the value's path, at the key's line
                        key = tok[1:-1] if "\\" not in tok else json.loads(tok)
                        top[2], top[3] = key, False
                        lines[top[1] + (key,)] = line
                        continue
                    path = top[1] + (top[2],)
                else:
                    path = top[1] + (top[2],)
                    lines[path] = line
            if c == "{":
                stack.append([True, path, None, True])
                continue
            if c == "[":
                stack.append([False, path, 0, False])
                continue
        if stack:           # a value ended (a scalar, or a closed container): its container moves on
            top = stack[-1]
            if top[0]:
                top[3] = True
            else:
                top[2] += 1
    return lines


def parse_json(text: str, file: str | None = None) -> Document:
    """Parse JSON strictly (its own syntax errors, with line); lines come from a YAML pass when first asked for.

    Bounded before parsing (:func:`_prescan_json`: at most :data:`MAX_VALUES` values), then by depth
    (:data:`MAX_DEPTH`).  A plan without problems never pays for its lines: the YAML pass runs when :meth:`Document.line` is first called, or at once when a key repeats
    (the JSON parser keeps the last; the YAML pass reports each with its line).
    """
    doc = Document(None, {}, file)
    try:
        _prescan_json(text)
    except _Refused as exc:
        doc.problems.append(Problem(exc.message, exc.hint, file=file, line=exc.line, code="limit"))
        return doc
    import json     # here, not at the top: a YAML plan never needs it

    repeated = []

    def mapping(pairs):
        out = dict(pairs)
        if len(out) != len(pairs):
            repeated.append(pairs)
        return out

    try:
        doc.data = json.loads(text, object_pairs_hook=mapping)
    except json.JSONDecodeError as exc:
        doc.problems.append(
            Problem(f"JSON syntax error: {exc.msg} (column {exc.colno})",
                    "fix the syntax at this line (a trailing comma or a missing quote are the usual causes)",
                    file=file, line=exc.lineno, code="syntax")
        )
        return doc
    except RecursionError:  # nested deeper than Python's parser goes: the YAML pass finds where
        doc.problems.extend(p for p in parse_yaml(text, file).problems if p.code == "limit")
        if not doc.problems:
            doc.problems.append(Problem(f"values nested more than {MAX_DEPTH} levels deep", _DEPTH_HINT,
                                        file=file, code="limit"))
        return doc
    except ValueError as exc:  # e.g. an integer of more than 4,300 digits
        doc.problems.append(Problem(f"cannot read the JSON: {exc.args[0] if exc.args else exc}",
                                    "write numbers of ordinary size", file=file, code="type"))
        return doc
    why = _too_big(doc.data)
    if why:
        # where the depth is passed: the YAML pass refuses there (its pre-scan checks depth first)
        located = parse_yaml(_SURROGATE_ESCAPE.sub(r"\\u003f", text), file)
        doc.problems.extend(p for p in located.problems if p.code == "limit")
        if not doc.problems:
            doc.problems.append(Problem(why, _DEPTH_HINT if "nested" in why else "split the plan into smaller ones",
                                        file=file, line=1, code="limit"))
        return doc

    def locate() -> dict[tuple, int]:
        if not repeated:
            return json_lines(text)
        # JSON is (almost) YAML: the YAML composer gives the lines, and each repeated key with its own.  libyaml refuses the escapes of
        # UTF-16 surrogates that JSON allows (\\ud83d\\ude00): for this pass they become '?' (the same
        # length: every line and column stays where it was).
        located = parse_yaml(_SURROGATE_ESCAPE.sub(r"\\u003f", text), file)
        if not located.problems:
            return located.lines
        # The YAML pass may object where JSON does not (duplicate keys): keep those findings.
        doc.problems.extend(p for p in located.problems if p.code == "duplicate-key")
        return {}

    if repeated:
        doc.lines = locate()
    else:
        doc.locate = locate
    return doc
