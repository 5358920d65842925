"""The decision policies by name: one place that makes them for replay, simulation and the service.

>>> from opportune.policies.named import make_policy
>>> make_policy("paper").name, make_policy("lookahead").name
('opportunistic', 'lookahead')
"""

from __future__ import annotations

#: The policies a cell can run, by name.  ``paper`` and ``opportunistic`` are the paper's rule.
POLICIES = ("lookahead", "paper", "opportunistic", "bin-first", "slack", "rollout")
#: The default policy of a cell and of `opportune evaluate`: the optimum's action where its programme
#: fits, else the exact look-ahead over ``slack`` (see docs/comparison.md); on plans too large for
#: either programme it decides as ``slack`` does.  The paper's rule stays one flag away (``paper``).
DEFAULT_POLICY = "lookahead"


class UnknownPolicy(ValueError):
    """A policy name that is not one of :data:`POLICIES`."""

    def __init__(self, name: str):
        super().__init__(f"unknown policy '{name}': choose from {', '.join(POLICIES)}")
        self.name = name


def make_policy(name: str, *, budget: float | None = None, seed: int = 0, visible: int = 2,
                capacity: int | None = None, costs=None, bin: str = "uniform", weights=None):
    """A new policy object for ``name`` (see :data:`POLICIES`), deciding within ``budget`` seconds.

    ``visible``, ``capacity``, ``costs``, ``bin`` and ``weights`` describe the world the look-ahead and
    the rollout score their actions in (the other policies need no model of the world).
    Raises :class:`UnknownPolicy`.
    """
    from opportune.policies import lookahead as lookahead_module, variants
    from opportune.policies.opportunistic import Opportunistic

    if name in ("paper", "opportunistic"):
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
