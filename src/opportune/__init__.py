"""opportune — least-commitment planning, scheduling and opportunistic execution.

The system of Fox & Kempf, "Planning, scheduling, and uncertainty in the
sequence of future events": a *plan* is a set of parts with the minimum
ordering constraints (possibly several strategies); a *schedule* is what has
been installed plus all admissible ways to finish; *execution* installs
whatever visible part can go in now, keeping the most future options.
"""

from opportune.formats import load_plan
from opportune.plan import Part, Plan, PlanError, Strategy, make_plan

__version__ = "0.1.0"

__all__ = ["Part", "Plan", "PlanError", "Strategy", "load_plan", "make_plan", "__version__"]
