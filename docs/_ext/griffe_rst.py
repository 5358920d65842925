"""A griffe extension for the API reference: the package's docstrings are written in reStructuredText
habits (Sphinx roles, ``double backticks``, doctest blocks), and mkdocstrings renders Markdown.

Two things would render badly as they are, so they are rewritten, in the documentation only:

* Sphinx roles (``:class:`~opportune.planning.plan.Plan```, ``:meth:`Schedule.count```) become code
  spans linked to the object's entry in the reference when it has one (an *optional*
  cross-reference: a target not in the reference is plain code, never a warning);
* doctest blocks (``>>>`` lines and their output) become fenced ``pycon`` blocks, instead of
  Markdown's nested block quotes, without their ``# doctest:`` directives.

Double backticks need nothing: in Markdown they are a code span too.
"""

from __future__ import annotations

import html
import re

import griffe

DIRECTIVE = re.compile(r"\s*#\s*doctest:.*$")   # ``# doctest: +SKIP``: for the doctest runner, not the reader
ROLE = re.compile(r":(?:py:)?(?:class|meth|func|mod|data|attr|exc|obj|const):`(~?)([^`<]+?)(?:\s*<([^`>]+)>)?`")


def _target(obj: griffe.Object, name: str) -> str | None:
    """The full path of ``name`` as written in ``obj``'s docstring, or None if it cannot be resolved."""
    name = name.strip().rstrip("()")
    if name.startswith("opportune."):
        return name
    scopes = [obj] + [p for p in _parents(obj)]
    head, _, rest = name.partition(".")
    for scope in scopes:
        try:
            if head in scope.members:
                found = scope.members[head].path
            else:
                found = scope.resolve(head)
        except (griffe.NameResolutionError, AttributeError, KeyError, ValueError):
            continue
        if found:
            return f"{found}.{rest}" if rest else found
    return None


def _parents(obj: griffe.Object):
    parent = obj.parent
    while parent is not None:
        yield parent
        parent = parent.parent


def _roles(obj: griffe.Object, text: str) -> str:
    def repl(m: re.Match) -> str:
        tilde, written, explicit = m.group(1), m.group(2), m.group(3)
        shown = written.strip()
        if explicit:                         # :class:`title <target>`
            target_name = explicit
        else:
            target_name = shown
            if tilde:
                shown = shown.rstrip("()").rsplit(".", 1)[-1] + ("()" if shown.endswith("()") else "")
        target = _target(obj, target_name)
        code = f"<code>{html.escape(shown)}</code>"
        if target is None:
            return code
        return f'<autoref identifier="{html.escape(target)}" optional>{code}</autoref>'

    return ROLE.sub(repl, text)


def _doctests(text: str) -> str:
    """Fence every doctest block (a run of lines from a ``>>>`` line to the next blank line)."""
    out: list[str] = []
    lines = text.split("\n")
    i, fenced = 0, False
    while i < len(lines):
        line = lines[i]
        stripped = line.lstrip()
        if stripped.startswith("```"):
            fenced = not fenced
        if not fenced and stripped.startswith(">>>"):
            indent = line[: len(line) - len(stripped)]
            out.append(f"{indent}```pycon")
            while i < len(lines) and lines[i].strip():
                out.append(DIRECTIVE.sub("", lines[i]))
                i += 1
            out.append(f"{indent}```")
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


class RestructuredDocstrings(griffe.Extension):
    """Rewrite Sphinx roles and doctest blocks of every docstring as Markdown (see the module)."""

    def on_object(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is None:
            return
        text = obj.docstring.value
        new = _doctests(_roles(obj, text))
        if new != text:
            obj.docstring.value = new
