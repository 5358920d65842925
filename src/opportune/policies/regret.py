"""A policy's gap over the optimum estimated from seeded runs, where its exact value does not fit.

The exact value of a policy (:class:`~opportune.policies.evaluate.PolicyEvaluator`, the pile's
:class:`~opportune.policies.pile.PileSolver`) asks the policy at every (state, look) it reaches: on a
20-25-part plan in the pile with 2-3 locations that is 1.5-1.9 million decisions of the fallback window,
about 75 CPU minutes, while the optimum's compiled programme takes seconds.  Where the optimum is known,
the gap needs far fewer decisions: by the performance-difference identity

    V_policy(start) - V*(start) = E_policy[ sum over looks t of ( Q*(s_t, a_t) - V*(s_t) ) ]

where ``Q*(s, a)`` is the expected cost of taking ``a`` at look ``s`` and acting optimally afterwards and
``V*(s)`` the least of them.  Each run follows the policy in the programme's own bin model (the same
states, looks and transitions its exact value sums over) and adds up its *regrets*, which are 0 wherever
the policy does what the optimum does: most looks of a near-optimal policy.  The mean over runs is an
unbiased estimate of the gap, with a far smaller spread than the runs' costs (which are also reported,
a second estimate of the same value, to check the first against).

Runs are seeded one by one (run ``i`` draws from ``Random(f"{seed}:{i}")``): the same seed gives the same
numbers however the runs are split.
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from math import sqrt
from statistics import fmean, stdev

from opportune.engine.deadline import as_deadline
from opportune.engine.tuning import REGRET_RUN_LOOKS, REGRET_TIE
from opportune.policies.evaluate import PolicyStuck
from opportune.policies.optimal import OutOfTime

__all__ = ["GapEstimate", "estimate_gap"]


@dataclass(frozen=True)
class GapEstimate:
    """What :func:`estimate_gap` measured.

    Attributes
    ----------
    gap : float
        The policy's expected cost over the optimum's, less one: the runs' mean regret over the optimum.
    se : float
        The standard error of ``gap`` (the regrets' sample deviation over the square root of the runs).
    optimum : float
        The optimum's expected cost from the start (exact).
    cost, cost_se : float
        The runs' mean cost and its standard error: a second, independent estimate of
        ``optimum * (1 + gap)``, with a larger spread.
    runs, looks, differing : int
        The runs, the looks decided in them, and the looks where the policy's action costs more than the
        optimum's (by more than 1e-12).
    seed : int
        The runs' seed.
    """

    gap: float
    se: float
    optimum: float
    cost: float
    cost_se: float
    runs: int
    looks: int
    differing: int
    seed: int


def _draw(rng: random.Random, counts: list[int], weights: list[float], k: int) -> list[int]:
    """``k`` units drawn without replacement, each with chance proportional to its part's weight (as the
    programme's look distribution), as part indices."""
    counts, taken = list(counts), []
    for _ in range(min(k, sum(counts))):
        mass = sum(c * w for c, w in zip(counts, weights))
        x, i = rng.random() * mass, 0
        while i < len(counts) - 1 and (counts[i] == 0 or x >= counts[i] * weights[i]):
            x -= counts[i] * weights[i]
            i += 1
        counts[i] -= 1
        taken.append(i)
    return taken


def _look_regret(optimum, policy, state: tuple, look: tuple[int, ...]) -> tuple[float, object, tuple | None]:
    """The policy's action at ``look`` (a sorted tuple of part indices), its regret over the optimum's, and
    the state's key after it (None for a shake)."""
    mask, cons, buffer = state
    key = optimum.policy_key(mask, cons, buffer)
    free = float("inf") if optimum.capacity is None else optimum.capacity - len(buffer)
    action = policy.choose_at(optimum.engine, mask, cons, tuple(buffer), free, tuple(optimum.ids[i] for i in look))
    _, best = optimum.best_action(key, look)
    try:
        value, nxt = optimum.action_value(key, look, action)
    except ValueError:
        raise ValueError(f"the policy chose {action} at a state where it is not a legal move") from None
    return value - best, action, nxt


def _run(optimum, policy, rng: random.Random, pile: bool) -> tuple[float, float, int, int]:
    """One run of ``policy`` in the programme's bin: (its regret, its cost, looks, looks that differ)."""
    engine, costs = optimum.engine, optimum.costs
    mask, cons, buffer = 0, engine.all_strategies, []
    regret = cost = 0.0
    looks = differing = 0
    window = None               # the pile's top (None: a fresh one, at the start or after a shake)
    while mask != engine.full:
        if looks >= REGRET_RUN_LOOKS:
            raise PolicyStuck(f"the policy took {looks:,} looks in one run without finishing: it shakes where "
                              "nothing changes (its expected time is not defined)")
        in_bin = list(optimum.bin_counts(optimum.policy_key(mask, cons, buffer)))
        if window is None or not pile:
            window = tuple(sorted(_draw(rng, in_bin, optimum.weights, optimum.visible)))
        r, action, nxt = _look_regret(optimum, policy, (mask, cons, buffer), window)
        r = r if r > REGRET_TIE else 0.0       # within the optimum's own tie tolerance: the same value, to rounding
        looks += 1
        differing += r > 0.0
        regret += r
        cost += costs.look
        if nxt is None:
            cost += costs.shake
            window = None
            continue
        cost += costs.move(action.part)
        mask, cons = nxt[0], nxt[1]
        i = optimum.plan.index(action.part)
        if action.kind == "buffer":
            buffer.append(action.part)
        elif action.source == "buffer":
            buffer.remove(action.part)
        if pile and not (action.kind == "install" and action.source == "buffer"):
            window = _taken(rng, window, i, in_bin)
    return regret, cost, looks, differing


def _taken(rng: random.Random, window: tuple[int, ...], i: int, in_bin: list[int]) -> tuple[int, ...]:
    """The pile's top after a unit of part ``i`` is taken from it: a uniformly drawn hidden unit comes up
    (``in_bin``: the bin's units before the move, the window's among them)."""
    rest = list(window)
    rest.remove(i)
    hidden = [c - window.count(j) for j, c in enumerate(in_bin)]
    if sum(hidden):
        rest += _draw(rng, hidden, [1.0] * len(hidden), 1)
    return tuple(sorted(rest))


def estimate_gap(optimum, policy, *, runs: int, seed: int = 0, pile: bool = False, deadline=None) -> GapEstimate:
    """Estimate a policy's gap over the optimum from ``runs`` seeded runs, by its regrets.

    Parameters
    ----------
    optimum : OptimalSolver
        The optimum's programme in the bin the policy is measured in (:func:`~opportune.policies.optimal.optimal_solver`,
        or :func:`~opportune.policies.pile.pile_solver` with ``pile=True``); its values are computed as the
        runs ask (call its ``value()`` first to bound the work by its ``max_states`` and ``deadline``).
    policy : Policy
        A policy deciding on the state alone (``choose_at``).
    runs : int
        The runs (at least 2).
    seed : int
        The runs' seed (run ``i`` draws from ``Random(f"{seed}:{i}")``).
    pile : bool
        The pile bin: the window stays until a unit is taken from it (else every look is a fresh draw).
    deadline : Deadline or float, optional
        Read after every run (None: no limit).

    Returns
    -------
    GapEstimate
        The gap, its standard error, the runs' own mean cost and what was counted.

    Raises
    ------
    ValueError
        Fewer than 2 runs, or the policy chose an action that is not legal at its state.
    PolicyStuck
        A run past :data:`~opportune.engine.tuning.REGRET_RUN_LOOKS` looks (the policy never finishes).
    OptimalTooLarge, OutOfTime
        The optimum's programme past its states or deadline; the runs past ``deadline``.

    Examples
    --------
    The paper's rule on a chain of four parts with two visible and one location: its exact gap is 0.0 (it
    is optimal there), and so is every run's regret:

    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.policies.opportunistic import Opportunistic
    >>> from opportune.policies.optimal import OptimalSolver
    >>> engine = OrderEngine(make_plan(["a", "b", "c", "d"], {"b": ["a"], "c": ["b"], "d": ["c"]}))
    >>> est = estimate_gap(OptimalSolver(engine, visible=2, capacity=1), Opportunistic(), runs=50)
    >>> est.gap, est.se, est.differing
    (0.0, 0.0, 0)
    """
    if runs < 2:
        raise ValueError(f"estimate_gap needs at least 2 runs, got {runs}")
    best = optimum.value()
    until = as_deadline(deadline)
    regrets, costs = [], []
    looks = differing = 0
    for i in range(runs):
        if until.expired():
            raise OutOfTime(f"the runs estimating the gap passed their deadline after {i:,} of {runs:,}")
        r, c, n, d = _run(optimum, policy, random.Random(f"{seed}:{i}"), pile)
        regrets.append(r)
        costs.append(c)
        looks, differing = looks + n, differing + d
    mean, se = _mean_se(regrets)
    cost, cost_se = _mean_se(costs)
    return GapEstimate(gap=mean / best, se=se / best, optimum=best, cost=cost, cost_se=cost_se, runs=runs,
                       looks=looks, differing=differing, seed=seed)



def _mean_se(values: list[float]) -> tuple[float, float]:
    """The mean and its standard error (at least 2 values)."""
    return fmean(values), stdev(values) / sqrt(len(values))
