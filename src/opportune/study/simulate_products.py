"""The multi-product study: N fixtures fed from one bin, against N separate cells and one product after another.

Three ways to build N products with one robot:

* ``together``: N fixtures, one bin holding every product's parts; each decision chooses
  the part and the fixture (:class:`~opportune.multi.MultiSequencer`'s translation).
* ``independent``: N cells, each with its own bin holding one product's parts, run one
  after the other (the time is the sum of the N cells' times).
* ``serial``: one fixture's worth of work at a time from the one bin holding every
  product's parts: product 1 is finished before product 2 starts, so parts of later
  products that turn up must be buffered or shaken back (the joint plan with
  :func:`~opportune.planning.products.several_products`'s ``serial``).

Each trial reports the time per product (the trial's time over N), motions, buffer moves
and shakes per product, the buffer's peak and its mean occupancy (parts in the buffer at a
look, averaged over the looks).  Trial ``k`` of every mode and policy draws from the
stream ``trial_seed(seed, k, 0)`` (independent cell ``i`` from ``trial_seed(seed, k + i * MAX_TRIALS, 0)``), so
the numbers do not depend on the machine.

Limits: :data:`~opportune.planning.products.MAX_PRODUCTS` products, :data:`MAX_TRIALS` trials, the
named policies, and each trial stops after :func:`step_limit` looks (reported as incomplete).

>>> from opportune import make_plan
>>> config = ProductsConfig((make_plan(["a", "b"], {"b": ["a"]}),) * 2, trials=20, policies=("paper",))
>>> result = run_products(config)
>>> sorted(result.trials), len(result.trials[("together", "paper")])
([('independent', 'paper'), ('serial', 'paper'), ('together', 'paper')], 20)
"""

from __future__ import annotations

import math
import random
import statistics
from collections.abc import Callable
from dataclasses import dataclass, field

from opportune.engine import OrderEngine
from opportune.engine.deadline import BudgetExceeded
from opportune.engine.schedule import MAX_STRATEGIES_EXACT
from opportune.multi import Layout, fit_policy
from opportune.planning.plan import Plan
from opportune.policies.named import FORMER_NAMES, POLICIES, current_names
from opportune.policies.named import make_policy as make_named_policy
from opportune.planning.products import (
    ProductsError,
    check_products,
    combine_products,
    kinds_in_bin,
)
from opportune.study.simulate import DECISION_CACHE_LIMIT, trial_seed
from opportune.worlds import TimeModel, make_world

__all__ = ["MAX_TRIALS", "MODES", "ProductsConfig", "ProductsResult", "run_products"]

#: The modes compared, in table order, with their labels.
MODES = ("together", "independent", "serial")
MODE_LABELS = {"together": "N fixtures, 1 bin", "independent": "N cells, N bins",
               "serial": "1 after another, 1 bin"}
#: Trials per mode and policy.
MAX_TRIALS = 1_000_000
#: Policies a multi-product study can run: every named policy (see :func:`opportune.multi.fit_policy`).
PRODUCT_POLICIES = POLICIES
METRICS = ("time", "motions", "buffer_moves", "shakes", "buffer_peak", "buffer_mean")


def step_limit(units: int) -> int:
    """Looks after which a trial of ``units`` install steps is stopped (as the single-product study)."""
    return 1000 + 200 * units * units


@dataclass(frozen=True)
class ProductsConfig:
    """Everything that determines a multi-product study's numbers: ``plans[i]`` is built on fixture ``i + 1``.

    Parameters
    ----------
    plans : tuple of Plan
        The products, one per fixture.
    policies : tuple of str, default ("paper", "lookahead")
        The policies compared (:data:`~opportune.policies.named.POLICIES`).
    modes : tuple of str, default MODES
        ``together`` (N fixtures, one bin), ``independent`` (N cells, N bins), ``serial`` (one product
        after another, one bin).
    trials : int, default 1000
        Trials per mode and policy, 1 to :data:`MAX_TRIALS`.
    seed : int, default 0
        The seed of every trial's bin.
    bin : str, default "uniform"
        ``uniform``, ``weighted``, ``pile`` or ``conveyor``.
    visible : int, default 2
        Parts seen per look.
    buffer_capacity : int, optional
        Buffer locations of a cell (``None``: unlimited).
    costs : TimeModel, optional
        The costs of motions, shakes and looks.
    decision_budget : float, optional
        Seconds per decision (``None``: exact).

    Examples
    --------
    >>> from opportune import make_plan
    >>> config = ProductsConfig((make_plan(["a", "b"], {"b": ["a"]}),) * 2, policies=("paper",), trials=20)
    >>> config.validate().n
    2
    """

    plans: tuple[Plan, ...]
    policies: tuple[str, ...] = ("paper", "lookahead")
    modes: tuple[str, ...] = MODES
    trials: int = 1000
    seed: int = 0
    bin: str = "uniform"
    visible: int = 2
    buffer_capacity: int | None = None
    costs: TimeModel = field(default_factory=TimeModel)
    decision_budget: float | None = None

    def __post_init__(self):
        # a former name is its policy's name now, each once: never two rows of one policy
        if any(p in FORMER_NAMES for p in self.policies) or len(set(self.policies)) < len(self.policies):
            object.__setattr__(self, "policies", current_names(self.policies)[0])

    @property
    def n(self) -> int:
        return len(self.plans)

    def validate(self) -> ProductsConfig:
        """Check the settings before any work.

        Returns
        -------
        ProductsConfig
            This configuration, unchanged.

        Raises
        ------
        ProductsError
            Naming the first setting out of bounds.

        Examples
        --------
        >>> from opportune import make_plan
        >>> ProductsConfig((make_plan(["a"]),), trials=0).validate()
        Traceback (most recent call last):
            ...
        opportune.planning.products.ProductsError: --trials must be a whole number from 1 to 1,000,000, not 0
        """
        check_products(len(self.plans), what="--products")
        for p in self.policies:
            if p not in PRODUCT_POLICIES:
                raise ProductsError(f"policy '{p}' cannot run several products: choose from "
                                    f"{', '.join(PRODUCT_POLICIES)}")
        for m in self.modes:
            if m not in MODES:
                raise ProductsError(f"unknown mode '{m}': choose from {', '.join(MODES)}")
        if isinstance(self.trials, bool) or not isinstance(self.trials, int) or not 1 <= self.trials <= MAX_TRIALS:
            raise ProductsError(f"--trials must be a whole number from 1 to {MAX_TRIALS:,}, not {self.trials!r}")
        if self.bin not in ("uniform", "weighted", "pile", "conveyor"):
            raise ProductsError(f"unknown bin model '{self.bin}': use uniform, weighted, pile or conveyor")
        if self.visible < 1:
            raise ProductsError("--visible must be at least 1")
        if self.buffer_capacity is not None and self.buffer_capacity < 0:
            raise ProductsError("--buffer-capacity must be ≥ 0")
        return self


@dataclass
class ProductsResult:
    """A multi-product study's trials: per ``(mode, policy)``, one dict of :data:`METRICS` per trial
    (all per product but the buffer's), and ``complete``.

    Made by :func:`run_products`.

    Parameters
    ----------
    config : ProductsConfig
        The study.
    trials : dict of (str, str) to list of dict
        The trials of each mode and policy.

    Examples
    --------
    >>> from opportune import make_plan
    >>> result = run_products(ProductsConfig((make_plan(["a", "b"], {"b": ["a"]}),) * 2, policies=("paper",),
    ...                                      trials=20))
    >>> list(result.trials)
    [('together', 'paper'), ('independent', 'paper'), ('serial', 'paper')]
    """

    config: ProductsConfig
    trials: dict[tuple[str, str], list[dict]]

    def summary(self) -> dict:
        """Means with 95% intervals (normal approximation) per mode and policy, as JSON values.

        Returns
        -------
        dict
            The settings, and ``rows``: one per mode and policy, with each metric's ``mean`` and
            ``ci95``, the trials, the complete ones and the buffer's maximum.

        Examples
        --------
        >>> from opportune import make_plan
        >>> result = run_products(ProductsConfig((make_plan(["a", "b"], {"b": ["a"]}),) * 2, policies=("paper",),
        ...                                      trials=20))
        >>> row = result.summary()["rows"][0]
        >>> row["mode"], row["trials"], round(row["time"]["mean"], 3)
        ('together', 20, 2.075)
        """
        rows = []
        for (mode, policy), trials in self.trials.items():
            row = {"mode": mode, "label": MODE_LABELS[mode], "policy": policy, "trials": len(trials),
                   "complete": sum(t["complete"] for t in trials)}
            for m in METRICS:
                values = [t[m] for t in trials]
                mean = statistics.fmean(values)
                half = 1.96 * statistics.stdev(values) / math.sqrt(len(values)) if len(values) > 1 else 0.0
                row[m] = {"mean": mean, "ci95": [mean - half, mean + half]}
            row["buffer_max"] = max(t["buffer_peak"] for t in trials)
            rows.append(row)
        cfg = self.config
        return {"products": cfg.n, "plans": [p.name for p in cfg.plans], "trials": cfg.trials, "seed": cfg.seed,
                "bin": cfg.bin, "visible": cfg.visible, "buffer_capacity": cfg.buffer_capacity,
                "costs": cfg.costs.to_dict(), "per_product": ["time", "motions", "buffer_moves", "shakes"],
                "rows": rows}


class CellRunner:
    """Trials of one policy on one joint plan (a cell of one or more fixtures fed from one bin).

    The loop keeps the state in machine form (the engine's installed mask, the buffer of
    kinds), translates looks of kinds into looks of units as :class:`~opportune.multi.MultiSequencer`
    does, and caches a deterministic policy's decisions.
    """

    def __init__(self, joint: Plan, policy: str, config: ProductsConfig):
        self.engine = engine = OrderEngine(joint)
        self.layout = layout = Layout(joint)
        weights = {kind: joint.parts[units[0][0]].visibility for kind, units in layout.units.items()}
        unit_costs = TimeModel(config.costs.motion, config.costs.shake, config.costs.look,
                               {u: c for u, k in layout.kind.items()
                                for c in [config.costs.parts.get(k)] if c is not None})
        chosen = make_named_policy(policy, budget=config.decision_budget, seed=config.seed, visible=config.visible,
                                   capacity=config.buffer_capacity, costs=unit_costs, bin=config.bin,
                                   weights={u: weights[k] for u, k in layout.kind.items()}
                                   if config.bin == "weighted" else None)
        self.policy = fit_policy(chosen, layout)
        self.world = make_world(config.bin, visible=config.visible, weights=weights)
        self.kinds = kinds_in_bin(joint)
        self.order = {k: i for i, k in enumerate(layout.units)}
        self.capacity = config.buffer_capacity
        self.costs = config.costs
        self.cache: dict | None = {} if getattr(self.policy, "deterministic", False) else None
        self.limit = step_limit(engine.n_units)
        self.index = {pid: i for i, pid in enumerate(joint.part_ids)}

    def _decide(self, mask: int, cons: int, buffer: tuple[str, ...], look: tuple[str, ...]) -> tuple[str, str | None]:
        lay, engine = self.layout, self.engine
        free = math.inf if self.capacity is None else self.capacity - len(buffer)
        a = self.policy.choose_at(engine, mask, cons, lay.view(engine, mask, buffer), free,
                                  lay.view(engine, mask, look))
        if a.kind == "buffer":
            return "buffer", lay.kind[a.part]
        if a.kind == "install":
            return ("install-buffer" if a.source == "buffer" else "install", a.part)
        return a.kind, None

    def run(self, rng: random.Random) -> dict:
        """One trial in a bin drawn from ``rng``: the costs of the whole cell (not per product)."""
        world, engine, lay, cache, costs = self.world, self.engine, self.layout, self.cache, self.costs
        world.reset(self.kinds, rng)
        order = self.order
        mask, cons, buffer = 0, engine.all_strategies, ()
        motions = buffer_moves = shakes = looks = peak = occupancy = 0
        t = 0.0
        while mask != engine.full and looks < self.limit:
            look = tuple(sorted(world.look(), key=order.__getitem__))
            looks += 1
            occupancy += len(buffer)
            key = (mask, cons, buffer, look)
            op = cache.get(key) if cache is not None else None
            if op is None:
                op = self._decide(mask, cons, buffer, look)
                if cache is not None:
                    if len(cache) >= DECISION_CACHE_LIMIT:
                        cache.clear()
                    cache[key] = op
            kind, part = op
            if kind in ("install", "install-buffer"):
                k = lay.kind[part]
                if kind == "install":
                    world.take(k)
                else:
                    i = buffer.index(k)
                    buffer = buffer[:i] + buffer[i + 1:]
                u = engine.next_unit(mask, self.index[part])
                cons = engine.consistent_after(mask, cons, u)
                mask |= 1 << u
                motions += 1
                t += costs.move(k)
            elif kind == "buffer":
                world.take(part)
                buffer = buffer + (part,)
                motions += 1
                buffer_moves += 1
                t += costs.move(part)
                peak = max(peak, len(buffer))
            elif kind == "shake":
                world.shake()
                shakes += 1
                t += costs.shake
            else:
                raise RuntimeError(f"policy {self.policy.name} said '{kind}' before every product was complete")
        t += looks * costs.look
        return {"time": t, "motions": motions, "buffer_moves": buffer_moves, "shakes": shakes, "looks": looks,
                "buffer_peak": peak, "occupancy": occupancy, "complete": mask == engine.full}


def check_countable(joint: Plan, budget: float | None) -> None:
    """Refuse a joint plan whose exact decisions cannot be counted: its strategies are the combinations of
    the products' (``s^N`` for N copies of a plan of ``s``), and exact counts of a union of strategies take
    inclusion–exclusion over at most :data:`~opportune.engine.schedule.MAX_STRATEGIES_EXACT` of them.
    With a decision budget, decisions estimate what they cannot count instead."""
    k = len(joint.strategies)
    if budget is None and k > MAX_STRATEGIES_EXACT:
        raise ProductsError(
            f"{joint.name} has {k} combinations of its products' strategies, and exact decisions count a union of at "
            f"most {MAX_STRATEGIES_EXACT} strategies: use fewer products, or let each decision estimate what it "
            "cannot count with --decision-budget 0.05")


def run_products(config: ProductsConfig, *, progress: Callable[[str, str, int], None] | None = None) -> ProductsResult:
    """Run every mode and policy of ``config``, in this process.  O(modes × policies × trials × looks).

    Parameters
    ----------
    config : ProductsConfig
        The study.
    progress : callable, optional
        Called as ``progress(mode, policy, trials)`` every 50 trials.

    Returns
    -------
    ProductsResult
        The trials of every mode and policy.

    Raises
    ------
    ProductsError
        For a setting out of bounds, or a joint plan whose decisions cannot be counted exactly
        (:func:`check_countable`; allow a ``decision_budget``).

    Examples
    --------
    >>> from opportune import make_plan
    >>> result = run_products(ProductsConfig((make_plan(["a", "b"], {"b": ["a"]}),) * 2, policies=("paper",),
    ...                                      trials=20, modes=("together",)))
    >>> len(result.trials[("together", "paper")])
    20
    """
    config.validate()
    check_countable(combine_products(config.plans), config.decision_budget)
    try:
        return _run(config, progress)
    except BudgetExceeded as exc:
        raise ProductsError(f"a decision's exact counts did not fit the engine's budget ({exc}): use fewer products, "
                            "or let each decision estimate what it cannot count with --decision-budget 0.05") from None


def _run(config: ProductsConfig, progress) -> ProductsResult:
    n = config.n
    out: dict[tuple[str, str], list[dict]] = {}
    for mode in config.modes:
        for policy in config.policies:
            if mode == "independent":
                runners = [CellRunner(combine_products([p]), policy, config) for p in config.plans]
            else:
                runners = [CellRunner(combine_products(config.plans, serial=mode == "serial"), policy, config)]
            trials = []
            for k in range(config.trials):
                if mode == "independent":
                    # cell i of trial k: its own stream (cell 0 shares the trial's, so one product is one run)
                    parts = [r.run(random.Random(trial_seed(config.seed, k + i * MAX_TRIALS, 0)))
                             for i, r in enumerate(runners)]
                else:
                    parts = [runners[0].run(random.Random(trial_seed(config.seed, k, 0)))]
                looks = sum(p["looks"] for p in parts)
                trials.append({
                    "time": sum(p["time"] for p in parts) / n,
                    "motions": sum(p["motions"] for p in parts) / n,
                    "buffer_moves": sum(p["buffer_moves"] for p in parts) / n,
                    "shakes": sum(p["shakes"] for p in parts) / n,
                    "buffer_peak": max(p["buffer_peak"] for p in parts),
                    "buffer_mean": sum(p["occupancy"] for p in parts) / max(1, looks),
                    "complete": all(p["complete"] for p in parts),
                })
                if progress and (k + 1) % 50 == 0:
                    progress(mode, policy, 50)
            out[(mode, policy)] = trials
    return ProductsResult(config, out)


def copies(plan: Plan, n: int) -> tuple[Plan, ...]:
    """``n`` copies of one plan, as :class:`ProductsConfig` takes them (checked: 1..MAX_PRODUCTS)."""
    return (plan,) * check_products(n, what="--products")

