"""Every public function and class the API reference shows carries the numpydoc sections a user calls from.

The objects are read from the reference pages themselves (``docs/reference/*.md``, each ``::: module``
block and its ``members`` list), so a name added to the reference is checked at once.  For each one,
and for every public method, class method and static method its class defines (or inherits, where
the block says ``inherited_members: true``, as the reference then shows them too):

* a docstring;
* ``Parameters``, naming every parameter of the signature (for a class, of its constructor), when it
  takes any, and no other;
* ``Returns`` (or ``Yields``) when it returns a value (its return annotation is not ``None``);
* ``Raises``, naming every exception class the function raises itself (``raise X(...)`` in its own
  body, not in functions it calls);
* ``Examples`` with at least one ``>>>`` line (tests/test_doctests.py runs them).

Properties and constants are data: they need none of the sections.  An exception class needs only
``Examples`` (where it is raised) unless it defines its own constructor, and so do an interface
(a ``typing.Protocol``) and an enumeration (an ``enum.Enum``: its members are its values).

Modules still waiting for this are listed in :data:`PENDING_MODULES` (by their exact names, as the
reference's ``:::`` blocks name them), and single objects in
:data:`PENDING`: each entry must still lack something (the test fails when it no longer does, so the
lists only shrink).
"""

from __future__ import annotations

import ast
import enum
import importlib
import inspect
import re
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "docs" / "reference"
BLOCK = re.compile(r"^::: (?P<module>\S+)\n(?:\s+options:\n\s+members: \[(?P<members>[^\]]*)\]"
                   r"(?P<inherited>\n\s+inherited_members: true)?)?", re.M)
SECTION = re.compile(r"^(?P<name>[A-Z][A-Za-z ]+)\n-{3,}[ \t]*$", re.M)
PARAMETER = re.compile(r"^(?P<names>\*{0,2}\w+(?:\s*,\s*\*{0,2}\w+)*)(?:\s*:.*)?$")

#: Modules of the reference whose docstrings are being rewritten with their code (none left; a module
#: listed here must still lack something, so the list only shrinks).
PENDING_MODULES: tuple[str, ...] = ()

#: Single objects of the other modules that still lack a section (``module:qualified.name``).
PENDING: frozenset[str] = frozenset()


def shown() -> list[tuple[str, str, object]]:
    """(module, qualified name, object) of every function, class and method the reference shows."""
    found = []
    for page in sorted(REFERENCE.glob("*.md")):
        for block in BLOCK.finditer(page.read_text(encoding="utf-8")):
            module = importlib.import_module(block["module"])
            for name in (n.strip() for n in (block["members"] or "").split(",")):
                if not name:
                    continue
                obj = getattr(module, name)
                if inspect.isclass(obj):
                    found.append((block["module"], name, obj))
                    found += [(block["module"], f"{name}.{k}", v) for k, v in _members(obj, block["inherited"])]
                elif callable(obj):
                    found.append((block["module"], name, obj))
    return found


def _members(cls, inherited) -> list[tuple[str, object]]:
    """The public methods of ``cls``: its own, and with ``inherited`` those of its bases it does not
    override (the nearest base's, as Python finds them)."""
    out: dict[str, object] = {}
    for base in cls.__mro__[:-1] if inherited else (cls,):   # object's members are Python's
        for k, v in vars(base).items():
            if not k.startswith("_") and _callable(v):
                out.setdefault(k, v)
    return list(out.items())


def _callable(member) -> bool:
    return isinstance(member, (classmethod, staticmethod)) or inspect.isfunction(member)


def sections(doc: str) -> dict[str, str]:
    """The numpydoc sections of a (dedented) docstring: name → text, up to the next section."""
    heads = list(SECTION.finditer(doc))
    return {h["name"].strip(): doc[h.end(): heads[i + 1].start() if i + 1 < len(heads) else len(doc)]
            for i, h in enumerate(heads)}


def documented_names(text: str) -> set[str]:
    """The names a Parameters section documents: its unindented ``name : type`` lines."""
    names = set()
    for line in text.splitlines():
        if line.strip() and not line[0].isspace() and (m := PARAMETER.match(line.strip())):
            names |= {n.strip().lstrip("*") for n in m["names"].split(",")}
    return names


def parameters(obj) -> list[str]:
    """The parameters a caller passes (``self`` and ``cls`` aside); a class's are its constructor's."""
    function = obj.__func__ if isinstance(obj, (classmethod, staticmethod)) else obj
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):
        return []
    return [p for p in signature.parameters if p not in ("self", "cls")]


def returns_value(function) -> bool:
    annotation = inspect.signature(function).return_annotation
    if annotation is inspect.Signature.empty:
        tree = _tree(function)
        return tree is not None and any(isinstance(n, ast.Return) and n.value is not None
                                        and not (isinstance(n.value, ast.Constant) and n.value.value is None)
                                        for n in _own_nodes(tree))
    return annotation not in (None, "None", "NoReturn", "Never")


def _tree(function):
    try:
        source = textwrap.dedent(inspect.getsource(function))
    except (OSError, TypeError):
        return None
    return ast.parse(source).body[0]


def _own_nodes(tree):
    """The nodes of a function's own body, not of functions or classes defined inside it."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        yield node
        stack += [c for c in ast.iter_child_nodes(node)
                  if not isinstance(c, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda))]


def raised(function) -> set[str]:
    """The exception classes a function raises in its own body (``raise Name(...)`` or ``raise Name``)."""
    tree = _tree(function)
    out = set()
    for node in _own_nodes(tree) if tree is not None else ():
        if isinstance(node, ast.Raise) and node.exc is not None:
            exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            name = exc.attr if isinstance(exc, ast.Attribute) else getattr(exc, "id", "")
            if name[:1].isupper():      # a class; a lower-case name re-raises a caught exception
                out.add(name)
    return out


def missing(obj) -> list[str]:
    """What ``obj``'s docstring lacks (empty: nothing)."""
    function = obj.__func__ if isinstance(obj, (classmethod, staticmethod)) else obj
    doc = inspect.getdoc(function)
    if not doc:
        return ["a docstring"]
    found = sections(doc)
    lacks = []
    is_exception = inspect.isclass(function) and issubclass(function, BaseException)
    is_protocol = getattr(function, "_is_protocol", False)     # an interface: nobody constructs it
    # an enumeration: its members are its values (its "constructor" looks one up, or is Python's
    # functional API for new enumerations, which no user calls on it)
    is_enum = inspect.isclass(function) and issubclass(function, enum.Enum)
    own_init = inspect.isclass(function) and "__init__" in vars(function)
    wanted = [] if is_protocol or is_enum or (is_exception and not own_init) else parameters(obj)
    if wanted:
        if "Parameters" not in found:
            lacks.append("Parameters")
        else:
            named = documented_names(found["Parameters"])
            lacks += [f"parameter {p!r} in Parameters" for p in wanted if p not in named]
            lacks += [f"no parameter {p!r} (documented in Parameters)" for p in sorted(named - set(wanted))]
    if not inspect.isclass(function):
        if returns_value(function) and not {"Returns", "Yields"} & set(found):
            lacks.append("Returns")
        for exc in sorted(raised(function)):
            if exc not in found.get("Raises", ""):
                lacks.append(f"{exc} in Raises")
    if ">>>" not in found.get("Examples", ""):
        lacks.append("Examples")
    return lacks


SHOWN = shown()
PENDING_ENTRIES = {f"{m}:{q}" for m, q, _ in SHOWN if m in PENDING_MODULES}


@pytest.mark.parametrize("module, name, obj", [s for s in SHOWN if f"{s[0]}:{s[1]}" not in PENDING | PENDING_ENTRIES],
                         ids=lambda v: v if isinstance(v, str) else "")
def test_a_shown_object_has_its_sections(module, name, obj):
    assert missing(obj) == [], f"{module}.{name} lacks {', '.join(missing(obj))}"


def test_the_pending_lists_only_shrink():
    keys = {f"{m}:{q}": o for m, q, o in SHOWN}
    assert PENDING <= set(keys), f"not in the reference (remove from PENDING): {sorted(PENDING - set(keys))}"
    done = sorted(k for k in PENDING if not missing(keys[k]))
    assert not done, f"complete now (remove from PENDING): {done}"
    for module in PENDING_MODULES:
        entries = [k for k in PENDING_ENTRIES if k.partition(":")[0] == module]
        if entries:     # a module gone from the reference needs no entry either
            assert any(missing(keys[k]) for k in entries), f"every object of {module} is complete: remove it"


def test_the_check_sees_what_is_missing():
    """The checks themselves: each lack is found on a function that has it, and none on one that has not."""

    def bare(plan, *, seed=0) -> int:
        """One line."""
        raise ValueError("no")

    def whole(plan, *, seed=0) -> int:
        """One line.

        Parameters
        ----------
        plan, seed : object
            What to read.

        Returns
        -------
        int
            Nothing much.

        Raises
        ------
        ValueError
            Always.

        Examples
        --------
        >>> 1
        1
        """
        raise ValueError("no")

    def stale(plan) -> None:
        """One line.

        Parameters
        ----------
        plan : object
            What to read.
        seed : int
            Gone from the signature.

        Examples
        --------
        >>> 1
        1
        """

    assert missing(bare) == ["Parameters", "Returns", "ValueError in Raises", "Examples"]
    assert missing(stale) == ["no parameter 'seed' (documented in Parameters)"]
    assert missing(whole) == []
    assert missing(lambda: None) == ["a docstring"]

    class Colour(enum.Enum):
        """One line.

        Examples
        --------
        >>> 1
        1
        """

        RED = "red"

    class Bare(enum.Enum):
        """One line."""

        RED = "red"

    assert missing(Colour) == [] and missing(Bare) == ["Examples"]    # no Parameters for Python's lookup
