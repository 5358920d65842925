"""The decision policies by name: one place that makes them for replay, simulation and the service.

>>> from opportune.policies.named import make_policy
>>> make_policy("paper").name, make_policy("lookahead").name
('paper', 'lookahead')

``opportunistic``, the paper's rule's former name, is still accepted, with a :class:`DeprecationWarning`
(:func:`current_name`); it is never a second policy beside ``paper``.
"""

from __future__ import annotations

import sys
import warnings

#: The policies a cell can run, by name.  ``paper`` is the paper's rule.
POLICIES = ("lookahead", "paper", "bin-first", "slack", "rollout")
#: Former names, still accepted: each one's name now.  The paper's rule was also ``opportunistic``;
#: two names of one policy gave two identical rows in a study, so one name stays.
FORMER_NAMES = {"opportunistic": "paper"}
#: The default policy of a cell and of `opportune evaluate`: the optimum's action where its programme
#: fits, else the exact look-ahead over ``slack`` (see docs/comparison.md); on plans too large for
#: either programme it decides as ``slack`` does.  The paper's rule stays one flag away (``paper``).
DEFAULT_POLICY = "lookahead"


def deprecation_note(name: str) -> str:
    """What to write instead of a former name (one sentence, for a warning or a note).

    >>> deprecation_note("opportunistic")
    "'opportunistic' is the former name of the paper's rule: write 'paper' (the old name will be removed)"
    """
    return (f"{name!r} is the former name of the paper's rule: write {FORMER_NAMES[name]!r} "
            "(the old name will be removed)")


def current_name(name: str, *, warn: bool = True) -> str:
    """``name``, or its name now when it is a former one (see :data:`FORMER_NAMES`): with ``warn``, a
    :class:`DeprecationWarning` attributed to the first caller outside this package.  Any other name is
    returned as it is (an unknown one is refused where it is used).

    >>> current_name("opportunistic", warn=False), current_name("lookahead")
    ('paper', 'lookahead')
    """
    if name not in FORMER_NAMES:
        return name
    if warn:
        warnings.warn(deprecation_note(name), DeprecationWarning, stacklevel=_outside_stacklevel())
    return FORMER_NAMES[name]


def current_names(names, *, warn: bool = True) -> tuple[tuple[str, ...], list[str]]:
    """``names`` with each former name replaced by its name now, each name once, in the first one's place;
    and the former names met (each once).  One warning at most, however many former names.

    >>> current_names(["opportunistic", "paper", "slack"], warn=False)
    (('paper', 'slack'), ['opportunistic'])
    """
    former = list(dict.fromkeys(n for n in names if n in FORMER_NAMES))
    if former and warn:
        warnings.warn("; ".join(deprecation_note(n) for n in former), DeprecationWarning,
                      stacklevel=_outside_stacklevel())
    return tuple(dict.fromkeys(FORMER_NAMES.get(n, n) for n in names)), former


def _outside_stacklevel() -> int:
    """The ``stacklevel`` of the first frame outside this package, for a warning issued by its caller: the
    user's line that gave the former name (Python 3.12's ``skip_file_prefixes``, on 3.11 too)."""
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_globals.get("__name__", "").split(".")[0] == "opportune":
        frame, level = frame.f_back, level + 1
    return level


class UnknownPolicy(ValueError):
    """A policy name that is not one of :data:`POLICIES` (a :class:`ValueError`).

    Parameters
    ----------
    name : str
        The name given.

    Examples
    --------
    >>> UnknownPolicy("best").name
    'best'
    """

    def __init__(self, name: str):
        super().__init__(f"unknown policy '{name}': choose from {', '.join(POLICIES)}")
        self.name = name


def make_policy(name: str, *, budget: float | None = None, seed: int = 0, visible: int = 2,
                capacity: int | None = None, costs=None, bin: str = "uniform", weights=None):
    """A new policy object by name, deciding within ``budget`` seconds.

    ``visible``, ``capacity``, ``costs``, ``bin`` and ``weights`` describe the world the look-ahead and
    the rollout score their actions in; the other policies need no model of the world.

    Parameters
    ----------
    name : str
        One of :data:`POLICIES`: ``lookahead`` (the default), ``paper`` (the paper's rule),
        ``bin-first``, ``slack`` or ``rollout``.  A former name (``opportunistic``) gives its policy,
        with a :class:`DeprecationWarning`.
    budget : float, optional
        Seconds per decision; ``None``: exact, however long it takes.
    seed : int, default 0
        The seed of the policy's estimates (and of the rollout's trials).
    visible : int, default 2
        Parts seen per look, in the world the look-ahead and the rollout score their actions in.
    capacity : int, optional
        Buffer locations in that world (``None``: unlimited).
    costs : CellModel, optional
        The cell's times, for the look-ahead and the rollout (``None``: counted actions).
    bin : str, default "uniform"
        The bin model of that world (``pile``: the look-ahead's pile programme).
    weights : mapping of str to float, optional
        The weighted bin's visibilities.

    Returns
    -------
    Policy
        A new policy, with no state shared with any other.

    Raises
    ------
    UnknownPolicy
        If ``name`` is not a policy's name (a :class:`ValueError`).

    Examples
    --------
    >>> make_policy("slack", budget=None).name
    'slack'
    >>> make_policy("best")
    Traceback (most recent call last):
        ...
    opportune.policies.named.UnknownPolicy: unknown policy 'best': choose from lookahead, paper, bin-first, slack, rollout
    """
    from opportune.policies import lookahead as lookahead_module, variants
    from opportune.policies.opportunistic import Opportunistic

    name = current_name(name)
    if name == "paper":
        return Opportunistic(budget=budget, seed=seed)
    if name == "bin-first":
        return variants.BinFirst(budget=budget, seed=seed)
    if name == "slack":
        return variants.Slack(budget=budget, seed=seed)
    if name in ("lookahead", "rollout"):
        settings = {"visible": visible, "capacity": capacity}
        if costs is not None:
            settings["costs"] = costs
        lookahead = lookahead_module.Lookahead(budget=budget, bin=bin, weights=weights, **settings)
        if name == "lookahead":
            return lookahead
        from opportune.policies.rollout import Rollout

        return Rollout(budget=budget, seed=seed, exact=lookahead, **settings)
    raise UnknownPolicy(name)
