"""The old path of :mod:`opportune.planning.plan` (and of :func:`~opportune.formats.loader.make_plan`,
which checks a plan as its file would be checked), for imports written before they moved."""

from opportune.formats.loader import make_plan  # noqa: F401
from opportune.planning.plan import *  # noqa: F401,F403
from opportune.planning.plan import Part, Plan, PlanError, Strategy  # noqa: F401
