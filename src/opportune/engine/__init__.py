"""The order engine: exact answers about all admissible sequences of a plan.

* :mod:`~opportune.engine.poset` — partial orders as bitmasks;
* :mod:`~opportune.engine.count` — counting linear extensions with a memo kept for the plan's life;
* :mod:`~opportune.engine.downsets` — an independent dynamic programme over down-sets (for checking);
* :mod:`~opportune.engine.estimate` — estimates with a stated error when exact counting is over budget;
* :mod:`~opportune.engine.schedule` — the schedule: installed parts plus all admissible completions,
  and the one counting entry (:meth:`~opportune.engine.schedule.Schedule.count_result` and its
  family): the exact methods, the hub split and the estimates are chosen behind it;
* :mod:`~opportune.engine.phases` — the counting methods behind that entry, one phase each, run in order;
* :mod:`~opportune.engine.exact`, :mod:`~opportune.engine.questions`, :mod:`~opportune.engine.memory` —
  the order engine's exact counts and deadline, its questions about a state, its memory upkeep;
* :mod:`~opportune.engine.result` — what a count answers, and counts as text;
* :mod:`~opportune.engine.tuning` — every numeric tuning constant of the engine, with why;
* :mod:`~opportune.engine.stats` — Student's t for the estimates' stated errors.
"""

from __future__ import annotations

from opportune._lazy import attach

__all__ = ["CountResult", "NotAdmissible", "OrderEngine", "Schedule", "compiled_core"]

# Loaded on first use (PEP 562): ``opportune.engine.poset`` alone (``opportune check``) does not
# load the counter, the hub and the schedule.
_LAZY = dict.fromkeys(__all__[:-1], "opportune.engine.schedule")

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from opportune.engine.schedule import CountResult, NotAdmissible, OrderEngine, Schedule


def compiled_core():
    """The compiled core (the module ``opportune._native``: the counter, relaxation Monte Carlo, the
    chains, the pile optimum), or None where it is missing or switched off with
    ``OPPORTUNE_PURE_PYTHON=1`` (then the pure-Python fallbacks run).  The one way above the engine to
    ask for it: what a report states, what the pile's optimum is built on.  O(1) once looked for.

    Returns
    -------
    module or None
        ``opportune._native``, or None when the pure-Python fallbacks run.

    Examples
    --------
    >>> core = compiled_core()
    >>> core is None or hasattr(core, "PileCore")
    True
    """
    from opportune.engine import native

    return native._native


__getattr__, __dir__ = attach(globals(), _LAZY, __all__)
