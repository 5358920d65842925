"""Plan files: YAML and JSON (one schema: partial orders or AND/OR graphs), SALBP ``.IN2``, checking, drawing."""

from __future__ import annotations

from opportune._lazy import attach

__all__ = [
    "AndOrGraph",
    "CheckResult",
    "Problem",
    "check_text",
    "load_plan",
    "plan_from_andor",
    "plan_from_dict",
    "read_plan",
]

# Loaded on first use (PEP 562): importing a submodule (``opportune.formats.summary``, ``.salbp``)
# does not load the others.
_LAZY = {"CheckResult": "opportune.formats.loader", "check_text": "opportune.formats.loader",
         "load_plan": "opportune.formats.loader", "plan_from_dict": "opportune.formats.loader",
         "read_plan": "opportune.formats.loader", "Problem": "opportune.formats.problems",
         "AndOrGraph": "opportune.formats.andor", "plan_from_andor": "opportune.formats.loader"}

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.formats.andor import AndOrGraph
    from opportune.formats.loader import CheckResult, check_text, load_plan, plan_from_andor, plan_from_dict, read_plan
    from opportune.formats.problems import Problem


__getattr__, __dir__ = attach(globals(), _LAZY, __all__)
