"""Every example in the package's docstrings runs and shows what it says (doctest, module by module)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import opportune

MODULES = sorted(m.name for m in pkgutil.walk_packages(opportune.__path__, "opportune.")
                 if not m.name.startswith("opportune._native") and m.name != "opportune.__main__")


@pytest.mark.parametrize("name", MODULES)
def test_the_docstring_examples_hold(name):
    try:
        module = importlib.import_module(name)
    except ImportError as exc:   # an optional extra that is not installed: nothing of it to test here
        pytest.skip(f"{name} needs {exc.name}")
    if module.__name__ != name:     # an old path kept for imports: its module's examples run under its own name
        pytest.skip(f"{name} is {module.__name__}")
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed (run it for details)"
