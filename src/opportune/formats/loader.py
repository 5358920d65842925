"""Reading plan files: YAML, JSON (one schema) and SALBP ``.IN2`` precedence graphs.

Every reader returns a :class:`~opportune.plan.Plan` or raises
:class:`~opportune.plan.PlanError` carrying *every* problem found, each with
its file, line and what to do.  YAML is read with PyYAML's safe loader only:
no tag in a plan file can run code.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from opportune.formats.problems import Problem
from opportune.plan import Plan, PlanError

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

    def line(self, path: tuple) -> int | None:
        """Line of ``path``, or of its nearest ancestor that has one."""
        while True:
            if path in self.lines:
                return self.lines[path]
            if not path:
                return None
            path = path[:-1]


@dataclass
class CheckResult:
    """Outcome of reading and checking a plan: the plan (if usable) and every finding."""

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


def detect_format(path: str | Path, text: str | None = None) -> str:
    """``"yaml"``, ``"json"`` or ``"in2"`` from the suffix, else from the content."""
    suffix = Path(path).suffix.lower()
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


def read_plan(path: str | Path) -> CheckResult:
    """Read and check a plan file of any supported format; never raises for bad content.

    ``salbp:NAME`` reads a SALBP graph shipped with the package (:mod:`opportune.datasets`).
    """
    if str(path).lower().startswith("salbp:"):
        from opportune import datasets

        try:
            path = datasets.salbp_path(str(path)[len("salbp:"):])
        except KeyError as exc:
            return CheckResult(None, [Problem(str(exc.args[0]), "use one of these names, e.g. salbp:KILBRID",
                                              code="io")])
    path = Path(path)
    name = str(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return CheckResult(None, [Problem(f"no such file: {name}", "check the path", code="io")])
    except IsADirectoryError:
        return CheckResult(None, [Problem(f"{name} is a directory, not a plan file", "give a .yaml, .json or .IN2 file", code="io")])
    except OSError as exc:
        return CheckResult(None, [Problem(f"cannot read {name}: {exc.strerror}", "check the file's permissions", code="io")])
    from opportune.formats.alb import check_alb_bytes, is_alb

    if is_alb(path, raw):
        return check_alb_bytes(raw, file=name)
    fmt = detect_format(path, raw[:200].decode("latin-1"))
    if fmt == "in2":
        from opportune.formats.salbp import check_in2_bytes

        return check_in2_bytes(raw, file=name)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        return CheckResult(None, [Problem("the file is not valid UTF-8 text", "save it as UTF-8", file=name, line=line, code="syntax")])
    return check_text(text, fmt=fmt, file=name)


def load_plan(path: str | Path) -> Plan:
    """Load a plan file (YAML, JSON or SALBP ``.IN2``); raise :class:`PlanError` with every problem.

    >>> plan = load_plan("examples/gearbox.yaml")  # doctest: +SKIP
    """
    result = read_plan(path)
    if not result.ok:
        raise PlanError(result.errors)
    return result.plan


def check_text(text: str, *, fmt: str = "yaml", file: str | None = None) -> CheckResult:
    """Parse and check plan text in ``fmt`` (``"yaml"`` or ``"json"``)."""
    doc = parse_json(text, file) if fmt == "json" else parse_yaml(text, file)
    if doc.problems:
        return CheckResult(None, doc.problems)
    from opportune.formats.validate import check_document

    return check_document(doc)


def plan_from_dict(data: Any, *, file: str | None = None) -> Plan:
    """Build a plan from already-parsed data in the file schema; raise :class:`PlanError` on errors."""
    from opportune.formats.validate import check_document

    result = check_document(Document(data, {}, file))
    if not result.ok:
        raise PlanError(result.errors)
    return result.plan


# ---------------------------------------------------------------- parsing


def parse_yaml(text: str, file: str | None = None) -> Document:
    """Safe-load YAML keeping each value's line; duplicate keys are problems (PyYAML would silently keep the last)."""
    import yaml  # here, not at the top: a SALBP graph or `--help` never needs PyYAML

    doc = Document(None, {}, file)
    try:
        loader = yaml.SafeLoader(text)
        try:
            node = loader.get_single_node()
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = exc.problem or exc.context or "invalid YAML"
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
    constructor = yaml.SafeLoader("")

    def build(n, path):
        doc.lines[path] = n.start_mark.line + 1
        if isinstance(n, yaml.MappingNode):
            out = {}
            for knode, vnode in n.value:
                key = build(knode, path + ("<key>",))
                if isinstance(key, (dict, list)):
                    doc.problems.append(
                        Problem("a mapping key must be a plain value", "use a part id or field name as key",
                                file=file, line=knode.start_mark.line + 1, code="type")
                    )
                    continue
                if key in out:
                    doc.problems.append(
                        Problem(
                            f"duplicate key {key!r}",
                            "each key may appear once per mapping: merge the two entries",
                            file=file,
                            line=knode.start_mark.line + 1,
                            parts=(str(key),),
                            code="duplicate-key",
                        )
                    )
                    continue
                out[key] = build(vnode, path + (key,))
                doc.lines[path + (key,)] = knode.start_mark.line + 1
            return out
        if isinstance(n, yaml.SequenceNode):
            return [build(item, path + (i,)) for i, item in enumerate(n.value)]
        try:
            return constructor.construct_object(n, deep=True)
        except yaml.YAMLError as exc:
            doc.problems.append(Problem(f"cannot read value: {exc}", "write a plain string or number",
                                        file=file, line=n.start_mark.line + 1, code="type"))
            return None

    doc.data = build(node, ())
    return doc


def parse_json(text: str, file: str | None = None) -> Document:
    """Parse JSON strictly (its own syntax errors, with line), then take lines from a YAML pass."""
    doc = Document(None, {}, file)
    try:
        doc.data = json.loads(text)
    except json.JSONDecodeError as exc:
        doc.problems.append(
            Problem(f"JSON syntax error: {exc.msg} (column {exc.colno})",
                    "fix the syntax at this line (a trailing comma or a missing quote are the usual causes)",
                    file=file, line=exc.lineno, code="syntax")
        )
        return doc
    # JSON is (almost) YAML: reuse the YAML composer only for line numbers.
    located = parse_yaml(text, file)
    if not located.problems:
        doc.lines = located.lines
    else:
        # The YAML pass may object where JSON does not (e.g. duplicate keys): keep those findings.
        doc.problems.extend(p for p in located.problems if p.code == "duplicate-key")
    return doc
