"""Plan files: YAML and JSON (one schema), SALBP ``.IN2`` graphs, checking and drawing."""

from __future__ import annotations

from typing import TYPE_CHECKING

__all__ = ["CheckResult", "Problem", "check_text", "load_plan", "plan_from_dict", "read_plan"]

# Loaded on first use (PEP 562): importing a submodule (``opportune.formats.summary``, ``.salbp``)
# does not load the others.
_LAZY = {"CheckResult": "opportune.formats.loader", "check_text": "opportune.formats.loader",
         "load_plan": "opportune.formats.loader", "plan_from_dict": "opportune.formats.loader",
         "read_plan": "opportune.formats.loader", "Problem": "opportune.formats.problems"}

if TYPE_CHECKING:
    from opportune.formats.loader import CheckResult, check_text, load_plan, plan_from_dict, read_plan
    from opportune.formats.problems import Problem


def __getattr__(name: str):
    if name in _LAZY:
        # __import__ rather than importlib.import_module: `python -X importtime` then shows what loaded
        value = getattr(__import__(_LAZY[name], fromlist=(name,)), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
