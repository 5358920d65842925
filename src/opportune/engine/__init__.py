"""The order engine: exact answers about all admissible sequences of a plan.

* :mod:`~opportune.engine.poset` — partial orders as bitmasks;
* :mod:`~opportune.engine.count` — counting linear extensions with a memo kept for the plan's life;
* :mod:`~opportune.engine.downsets` — an independent dynamic programme over down-sets (for checking);
* :mod:`~opportune.engine.estimate` — estimates with a stated error when exact counting is over budget;
* :mod:`~opportune.engine.schedule` — the schedule: installed parts plus all admissible completions.
"""

from opportune.engine.schedule import CountResult, NotAdmissible, OrderEngine, Schedule

__all__ = ["CountResult", "NotAdmissible", "OrderEngine", "Schedule"]
