"""opportune — least-commitment planning, scheduling and opportunistic execution.

The system of Fox & Kempf, "Planning, scheduling, and uncertainty in the
sequence of future events": a *plan* is a set of parts with the minimum
ordering constraints (possibly several strategies); a *schedule* is what has
been installed plus all admissible ways to finish; *execution* installs
whatever visible part can go in now, keeping the most future options.
"""

from __future__ import annotations

from opportune._lazy import attach

# not `from typing import TYPE_CHECKING`: importing typing is a tenth of `opportune count --help`'s
# start-up, and type checkers read a module-level TYPE_CHECKING = False the same way
TYPE_CHECKING = False

__version__ = "0.2.0.dev0"

__all__ = ["NotAdmissible", "OrderEngine", "Part", "Plan", "PlanError", "Schedule", "Sequencer", "Strategy",
           "load_plan", "make_plan", "__version__"]

# The names below load on first use (PEP 562), so that ``import opportune.cli`` (every run of the
# command line, `--help` included) does not pay for the plan loader and PyYAML.
_LAZY = {"load_plan": "opportune.formats.loader", "Part": "opportune.planning.plan", "Plan": "opportune.planning.plan",
         "PlanError": "opportune.planning.plan", "Strategy": "opportune.planning.plan", "make_plan": "opportune.formats.loader",
         "Schedule": "opportune.engine.schedule", "OrderEngine": "opportune.engine.schedule",
         "NotAdmissible": "opportune.engine.schedule", "Sequencer": "opportune.sequencer"}

if TYPE_CHECKING:
    from opportune.engine.schedule import NotAdmissible, OrderEngine, Schedule
    from opportune.formats.loader import load_plan, make_plan
    from opportune.planning.plan import Part, Plan, PlanError, Strategy
    from opportune.sequencer import Sequencer


__getattr__, __dir__ = attach(globals(), _LAZY, __all__)
