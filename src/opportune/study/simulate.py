"""Monte Carlo study: every strategy of the paper in a simulated bin, at scale, reproducibly.

The simulated world acts on the same policies as the sequencer (one decision
path); the trial loop here only keeps the cell's state in machine form
(bitmasks) and memoises the decisions of deterministic policies, which is
what makes large studies fast (docs/comparison.md gives the measured rates).
:func:`run_trial_with_sequencer` plays a trial through the full
:class:`~opportune.sequencer.Sequencer` instead; the tests check that both
give identical trials.

Reproducibility: trial *i* of a study with seed *s* draws its bin from its own
stream ``random.Random(trial_seed(s, i, 0))`` (a random policy from a second one), so
the numbers do not depend on how trials are split between workers or
executors.
"""

from __future__ import annotations

import gc
import math
import random
import time as _time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, fields
from typing import Callable

from opportune.engine import OrderEngine
from opportune.engine.deadline import BudgetExceeded
from opportune.engine.schedule import Schedule
from opportune.planning.plan import Plan
from opportune.policies.base import Action
from opportune.policies.named import DEFAULT_POLICY, FORMER_NAMES, POLICIES, current_names
from opportune.policies.named import make_policy as make_named_policy
from opportune.sequencer import State
from opportune.worlds import BIN_NAMES, CellModel, PalletWorld, TimeModel, World, make_world

#: The study's default strategies: the paper's comparison, and the default policy beside the paper's rule.
STRATEGIES = ("pallet", "shake", "kitting", "buffer", "quantify", "paper", DEFAULT_POLICY, "random", "optimal")
#: Policies beyond the paper's (policies/variants.py, rollout.py), run when asked for by name.  A former
#: name (``opportunistic``, the paper's rule: policies/named.py) is accepted with a DeprecationWarning.
MORE_STRATEGIES = ("bin-first", "slack", "rollout")
ALL_STRATEGIES = STRATEGIES + MORE_STRATEGIES
MARKOV_BINS = ("uniform", "weighted")
OPTIMAL_BINS = MARKOV_BINS + ("pile",)   # bins whose exact optimum is computed (policies/optimal.py, pile.py)


class StudyError(ValueError):
    """A study that cannot be run as asked (a user mistake: the message says what to change).

    Examples
    --------
    >>> from opportune import load_plan
    >>> StudyConfig(load_plan("example:gearbox"), bin="tray").validate()
    Traceback (most recent call last):
        ...
    opportune.study.simulate.StudyError: unknown bin model 'tray': use uniform, weighted, pile, conveyor or physics
    """


class StrategyUnavailable(StudyError):
    """One strategy cannot be run on this plan (too large for it); the others can."""

    def __init__(self, strategy: str, message: str):
        self.strategy = strategy
        super().__init__(message)


COUNTING_STRATEGIES = ("paper", "bin-first", "slack", "lookahead")  # decide by exact counts of the admissible completions, at every look


@dataclass(frozen=True)
class StudyConfig:
    """Everything that determines a study's numbers.

    Parameters
    ----------
    plan : Plan
        The plan assembled in every trial.
    strategies : tuple of str, default STRATEGIES
        The strategies compared: the paper's (``pallet``, ``shake``, ``kitting``, ``buffer``,
        ``quantify``, ``paper``), ``lookahead``, ``random`` and ``optimal``, and those of
        :data:`MORE_STRATEGIES`.  A former name is replaced by its name now, each name kept once.
    trials : int, default 10000
        Trials per strategy; trial *i* of every strategy sees the same bin.
    seed : int, default 0
        The seed of every trial's bin (and of random policies).
    bin : str, default "uniform"
        The bin model: one of :data:`~opportune.worlds.BIN_NAMES`.
    visible : int, default 2
        Parts seen per look.
    buffer_capacity : int, optional
        Buffer locations (``None``: unlimited).
    costs : TimeModel, optional
        The costs of motions, shakes and looks (default: one per motion and shake).
    training_runs : int, default 200
        Runs that train ``quantify``'s statistics.
    optimal_states : int, default 500000
        The most states the optimum's programme may store.
    count_time_limit : float, default 10.0
        Seconds the first look's exact counts may take (see :func:`prepare`).
    max_steps : int, optional
        Steps after which a trial is given up as incomplete (``None``: 1000 + 200 × units²).
    decision_budget : float, optional
        Seconds per decision of the counting policies (``None``: exact, reproducible).
    cell : CellModel, optional
        The cell's times, for the cycle time in seconds.

    Examples
    --------
    >>> from opportune import load_plan
    >>> config = StudyConfig(load_plan("example:gearbox"), strategies=("paper", "shake"), trials=50, seed=1)
    >>> config.validate().trials
    50
    """

    plan: Plan
    strategies: tuple[str, ...] = STRATEGIES
    trials: int = 10_000
    seed: int = 0
    bin: str = "uniform"
    visible: int = 2
    buffer_capacity: int | None = None
    costs: TimeModel = field(default_factory=TimeModel)
    training_runs: int = 200
    optimal_states: int = 500_000
    count_time_limit: float = 10.0  # seconds the first look's exact counts may take (see prepare)
    max_steps: int | None = None
    decision_budget: float | None = None  # seconds per opportunistic decision (None: exact, reproducible)
    cell: CellModel = field(default_factory=CellModel)  # the cell's times: cycle time in seconds

    def __post_init__(self):
        # a former name is its policy's name now, each once: never two rows of one policy
        if any(s in FORMER_NAMES for s in self.strategies) or len(set(self.strategies)) < len(self.strategies):
            object.__setattr__(self, "strategies", current_names(self.strategies)[0])

    def validate(self) -> "StudyConfig":
        """Check the settings before any work.

        Returns
        -------
        StudyConfig
            This configuration, unchanged.

        Raises
        ------
        StudyError
            Naming the setting to change: an unknown strategy or bin, a strategy that does not take the
            plan written as ways (:data:`~opportune.formats.ways.WAYS_POLICIES`), ``optimal`` in a bin without an
            exact optimum, a physical bin the plan does not fit, or a count, limit or budget out of range.

        Examples
        --------
        >>> from opportune import load_plan
        >>> StudyConfig(load_plan("example:gearbox"), trials=0).validate()
        Traceback (most recent call last):
            ...
        opportune.study.simulate.StudyError: --trials must be at least 1
        """
        unknown = [s for s in self.strategies if s not in ALL_STRATEGIES]
        if unknown:
            raise StudyError(f"unknown strategy '{unknown[0]}': choose from {', '.join(ALL_STRATEGIES)}")
        if self.plan.is_ways:
            from opportune.formats.ways import WAYS_POLICIES, not_for_ways

            refused = [s for s in self.strategies if s not in WAYS_POLICIES]
            if refused:
                raise StudyError(not_for_ways(f"the strategy '{refused[0]}'"))
        if self.bin not in BIN_NAMES:
            raise StudyError(f"unknown bin model '{self.bin}': use {', '.join(BIN_NAMES[:-1])} or {BIN_NAMES[-1]}")
        if self.bin == "physics":
            self._check_physics()
        if "optimal" in self.strategies and self.bin not in OPTIMAL_BINS:
            raise StudyError(f"'optimal' is defined for the uniform, weighted and pile bins, not '{self.bin}': "
                             "leave it out of --strategies or change --bin")
        if self.trials < 1:
            raise StudyError("--trials must be at least 1")
        if self.visible < 1:
            raise StudyError("--visible must be at least 1")
        if self.buffer_capacity is not None and self.buffer_capacity < 0:
            raise StudyError("--buffer-capacity must be ≥ 0")
        if self.decision_budget is not None and not self.decision_budget > 0:
            raise StudyError("--decision-budget must be a positive number of seconds")
        if self.buffer_capacity == 0 and "buffer" in self.strategies:
            pass  # allowed: the buffer strategy then shakes like `shake`
        return self

    def _check_physics(self) -> None:
        """The physical bin's bounds on this plan, and MuJoCo, before any model is built."""
        from opportune.worlds import physics as ph

        settings = dict(self.plan.simulation.get("physics") or {})
        units = [p.id for p in self.plan.parts for _ in range(p.quantity)]
        try:
            ph.check_bin(units, self.geometry, settings.get("bin", ph.DEFAULT_BIN),
                         settings.get("settle_steps", ph.DEFAULT_SETTLE_STEPS),
                         settings.get("visible_fraction", ph.VISIBLE_FRACTION))
            ph.require_mujoco()
        except ph.PhysicsError as exc:
            raise StudyError(str(exc)) from None

    @property
    def geometry(self) -> dict[str, tuple]:
        """Each part's shape in the physical bin, where the plan gives one."""
        return {p.id: p.geometry for p in self.plan.parts if p.geometry is not None}

    def settings(self) -> dict:
        """The settings, the plan aside, as plain JSON values (``results.json``'s ``provenance.study``).

        Returns
        -------
        dict
            One entry per setting; :meth:`from_settings` reads it back.

        Examples
        --------
        >>> from opportune import load_plan
        >>> settings = StudyConfig(load_plan("example:gearbox"), trials=50).settings()
        >>> settings["trials"], settings["bin"]
        (50, 'uniform')
        """
        return {"strategies": list(self.strategies), "trials": self.trials, "seed": self.seed, "bin": self.bin,
                "visible": self.visible, "buffer_capacity": self.buffer_capacity, "costs": self.costs.to_dict(),
                "training_runs": self.training_runs, "optimal_states": self.optimal_states,
                "count_time_limit": self.count_time_limit, "max_steps": self.max_steps,
                "decision_budget": self.decision_budget, "cell": self.cell.to_dict()}

    @classmethod
    def from_settings(cls, plan: Plan, settings: dict) -> "StudyConfig":
        """The study :meth:`settings` describe, on ``plan``.

        Parameters
        ----------
        plan : Plan
            The plan the study runs on.
        settings : dict
            What :meth:`settings` wrote (a recorded study's ``provenance.study``).

        Returns
        -------
        StudyConfig
            The configuration, validated.

        Raises
        ------
        StudyError
            If a setting is missing, unknown or malformed, or the configuration is not valid.

        Examples
        --------
        >>> from opportune import load_plan
        >>> config = StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=50)
        >>> StudyConfig.from_settings(config.plan, config.settings()) == config
        True
        """
        try:
            values = dict(settings)
            costs = dict(values.pop("costs"))
            values["costs"] = TimeModel(motion=float(costs["motion"]), shake=float(costs["shake"]),
                                        look=float(costs["look"]),
                                        parts={str(k): float(v) for k, v in dict(costs.get("parts") or {}).items()})
            # a study recorded under a former name runs under the name now (the record is not the user's writing)
            values["strategies"] = current_names([str(s) for s in values["strategies"]], warn=False)[0]
            if "cell" in values:   # (a study recorded before cycle times in seconds has none: the defaults)
                values["cell"] = CellModel.from_dict(values["cell"], plan.part_ids)
            unknown = set(values) - {f.name for f in fields(cls)}
            if unknown:
                raise StudyError(f"unknown study setting(s): {', '.join(sorted(unknown))}")
            for name, kind in (("trials", int), ("seed", int), ("visible", int), ("training_runs", int),
                               ("optimal_states", int), ("count_time_limit", float)):
                if name in values and (isinstance(values[name], bool) or not isinstance(values[name], (int, float))):
                    raise StudyError(f"study setting '{name}' must be a number, not {values[name]!r}")
                if name in values:
                    values[name] = kind(values[name])
            return cls(plan=plan, **values).validate()
        except StudyError:
            raise
        except KeyError as exc:
            raise StudyError(f"the recorded study settings lack {exc}") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise StudyError(f"the recorded study settings are incomplete or malformed ({type(exc).__name__}: {exc})") \
                from None

    @property
    def weights(self) -> dict[str, float]:
        return {p.id: p.visibility for p in self.plan.parts}

    @property
    def step_limit(self) -> int:
        units = self.plan.n_units
        return self.max_steps or 1000 + 200 * units * units


@dataclass
class TrialResult:
    """The costs of one trial of one strategy.

    Parameters
    ----------
    strategy : str
        The strategy.
    trial : int
        The trial's number (its bin's stream).
    motions, buffer_moves, shakes, looks : int
        What the trial took: robot motions (buffer moves included), moves into a buffer location,
        shakes and looks.
    buffer_peak : int
        The most buffer locations held at once.
    time : float
        The trial's cost in the study's :class:`~opportune.planning.costs.TimeModel`.
    cycle_seconds : float, default 0.0
        The cycle time in seconds, in the study's cell model.
    complete : bool, default True
        Whether the assembly was completed within the step limit.

    Examples
    --------
    >>> from opportune import load_plan
    >>> result = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=5), workers=1)
    >>> trial = result.trials["paper"][0]
    >>> trial.strategy, trial.trial, trial.complete
    ('paper', 0, True)
    """

    strategy: str
    trial: int
    motions: int
    buffer_moves: int
    shakes: int
    looks: int
    buffer_peak: int
    time: float
    cycle_seconds: float = 0.0   # the cycle time in seconds, in the study's cell model
    complete: bool = True

    def row(self) -> tuple:
        """The trial as a row of ``trials.csv``.

        Returns
        -------
        tuple
            ``strategy``, ``trial``, the costs in the order of the fields, and ``complete``.

        Examples
        --------
        >>> TrialResult("paper", 0, 15, 5, 0, 15, 5, 15.0, 81.5).row()
        ('paper', 0, 15, 5, 0, 15, 5, 15.0, 81.5, True)
        """
        return (self.strategy, self.trial, self.motions, self.buffer_moves, self.shakes, self.looks,
                self.buffer_peak, self.time, self.cycle_seconds, self.complete)


METRICS = ("motions", "buffer_moves", "shakes", "looks", "buffer_peak", "time", "cycle_seconds")
DECISION_CACHE_LIMIT = 200_000  # cached decisions per strategy and worker before starting afresh
CACHE_PROBE_LOOKS = 2_000  # looks after which a decision cache that rarely answers is dropped
CACHE_MIN_HITS = 0.2  # the share of looks a decision cache must answer to be kept
ALIKE_KEY_UNITS = 24  # plans up to this many units cache decisions by the policy's decision_key


# ---------------------------------------------------------------- preparing strategies


@dataclass
class Prepared:
    """Heavy, shareable preparation: the optimum's value table and quantify's statistics."""

    sequence: tuple[str, ...]
    optimal_values: dict | None = None
    optimal_start: float | None = None
    optimal_states: int = 0
    optimal_seconds: float = 0.0
    quantify_rank: dict | None = None
    seconds: float = 0.0   # wall seconds prepare() took (part of the study's wall_seconds)


def prepare(config: StudyConfig, engine: OrderEngine | None = None) -> Prepared:
    """Compute once, in the parent, what every worker needs: the optimum's values, quantify's
    statistics, the planned sequence, and the first state's counts.

    Parameters
    ----------
    config : StudyConfig
        The study.
    engine : OrderEngine, optional
        The plan's engine, whose memos the trials share (``None``: a new one).

    Returns
    -------
    Prepared
        The shareable preparation, for :func:`run_study`'s ``prepared``.

    Raises
    ------
    StrategyUnavailable
        If a strategy cannot run on this plan: a counting policy whose first look's exact counts do
        not finish within ``count_time_limit`` (without a decision budget), or an optimum over
        ``optimal_states`` states.  It is a :class:`StudyError` naming the strategy.

    Examples
    --------
    >>> from opportune import load_plan
    >>> prepared = prepare(StudyConfig(load_plan("example:gearbox"), strategies=("paper",), trials=5))
    >>> prepared.sequence[:3]
    ('ca', 'ba', 'rl')
    """
    from opportune.policies.fixed import Quantify, planned_sequence

    began = _time.perf_counter()
    engine = engine or OrderEngine(config.plan)
    prepared = Prepared(sequence=planned_sequence(engine))
    counting = [s for s in config.strategies if s in COUNTING_STRATEGIES]
    if counting and config.decision_budget is not None:
        # Budgeted decisions estimate what they cannot count: nothing to refuse; count the first
        # state now (within the time limit) so that the workers start from a chosen way of counting.
        Schedule(engine).warm_up(config.count_time_limit)
    elif counting:
        # Such a policy counts at every look: if the first look's counts do not finish in reasonable
        # time, no trial will.  Say so now rather than hang (the counts made stay in the memo).
        limit = config.count_time_limit
        try:
            # the rule needs counts (what to install) and expected positions (what to buffer): both for
            # the first state, under one deadline (on ARC111 the counts fit in a second, the positions
            # through its hub take about a second per part)
            with engine.time_limited(limit), engine.deadline(_time.perf_counter() + limit):
                first = Schedule(engine)
                first.options()
                first.position_sums_for(set(config.plan.part_ids))
        except BudgetExceeded as exc:
            within, more = ((f"in {limit:g} s", ", or allow more time with --count-time-limit")
                            if exc.reason == "time" else ("within the counter's memory budget", ""))
            raise StrategyUnavailable(counting[0], (
                f"'{counting[0]}' ranks the candidates by exact counts of admissible completions at every look, "
                f"and on {config.plan.name} ({config.plan.n_units} parts) the counts and expected positions of the "
                f"first look do not "
                f"finish {within}: leave it out with --strategies{more}, or let it decide within a time budget "
                f"(estimating what it cannot count) with --decision-budget 0.05")) from None
    if "optimal" in config.strategies:
        from opportune.policies.optimal import OptimalTooLarge

        t0 = _time.perf_counter()
        solver = _solver(engine, config)
        try:
            prepared.optimal_start = solver.value()
        except OptimalTooLarge as exc:
            raise StrategyUnavailable("optimal", str(exc)) from None
        prepared.optimal_values = solver._values
        prepared.optimal_states = solver.states
        prepared.optimal_seconds = _time.perf_counter() - t0
    if "quantify" in config.strategies:
        q = Quantify.train(engine, _world(config, prepared), runs=config.training_runs, seed=config.seed)
        prepared.quantify_rank = q.mean_rank
    prepared.seconds = _time.perf_counter() - began
    return prepared


def _solver(engine, config):
    from opportune.policies.optimal import optimal_solver

    if config.bin == "pile":
        from opportune.policies.pile import pile_solver

        # compiled where the core is built: its values stay in the core (a worker solves again, ~1 s a million states)
        return pile_solver(engine, visible=config.visible, capacity=config.buffer_capacity, costs=config.costs,
                          max_states=config.optimal_states)

    # compiled where the core is built, on the plan with its interchangeable parts merged (the Python
    # programme's memo is handed to the workers; the compiled one's stays in the core: a worker solves again)
    return optimal_solver(engine, visible=config.visible, capacity=config.buffer_capacity, costs=config.costs,
                          weights=config.weights if config.bin == "weighted" else None,
                          max_states=config.optimal_states)


def _world(config: StudyConfig, prepared: Prepared, strategy: str = "") -> World:
    if strategy == "pallet":
        return PalletWorld(prepared.sequence)
    return make_world(config.bin, visible=config.visible, weights=config.weights, geometry=config.geometry,
                      physics=config.plan.simulation.get("physics"))


def make_policy(strategy: str, engine: OrderEngine, config: StudyConfig, prepared: Prepared):
    """The policy object for a strategy name (all implement the sequencer's Policy interface)."""
    from opportune.policies import fixed
    from opportune.policies.random_policy import RandomChoice

    if strategy == "pallet":
        return fixed.Pallet(prepared.sequence)
    if strategy == "shake":
        return fixed.ShakeUntilVisible(prepared.sequence)
    if strategy == "kitting":
        return fixed.Kitting(prepared.sequence)
    if strategy == "buffer":
        return fixed.BufferFixed(prepared.sequence)
    if strategy == "quantify":
        return fixed.Quantify(engine, prepared.quantify_rank or {}, config.training_runs)
    if strategy in POLICIES:
        return make_named_policy(strategy, budget=config.decision_budget, seed=config.seed, visible=config.visible,
                                 capacity=capacity_for(strategy, config), costs=config.costs, bin=config.bin,
                                 weights=config.weights if config.bin == "weighted" else None)
    if strategy == "random":
        return RandomChoice()
    if strategy == "optimal":
        from opportune.policies.optimal import Optimal

        solver = _solver(engine, config)
        solver._values.update(prepared.optimal_values or {})
        return Optimal(solver)
    raise StudyError(f"unknown strategy '{strategy}'")


def capacity_for(strategy: str, config: StudyConfig) -> int | None:
    """Kitting lays every part out (its own locations); pallet and shake never buffer."""
    return None if strategy == "kitting" else config.buffer_capacity


# ---------------------------------------------------------------- one trial


class TrialRunner:
    """Runs trials of one strategy; keeps decision and transition caches across trials.

    The decision cache is dropped once it is seen to answer few looks (see :meth:`_review_cache`).
    """

    def __init__(self, strategy: str, engine: OrderEngine, config: StudyConfig, prepared: Prepared):
        self.strategy = strategy
        self.engine = engine
        self.config = config
        self.policy = make_policy(strategy, engine, config, prepared)
        self.world = _world(config, prepared, strategy)
        self.capacity = capacity_for(strategy, config)
        self.costs = config.costs
        self.units = [p.id for p in engine.plan.parts for _ in range(p.quantity)]
        self.index = {p: i for i, p in enumerate(engine.plan.part_ids)}
        self.cache: dict | None = {} if getattr(self.policy, "deterministic", False) else None
        self.transitions: dict = {}
        self.move = {p: self.costs.move(p) for p in engine.plan.part_ids}
        cell = config.cell   # seconds of each motion, by what it does (op 0, 1, 2 of the trial loop)
        self.seconds = [{p: cell.install_seconds(p, "bin") for p in engine.plan.part_ids},
                        {p: cell.install_seconds(p, "buffer") for p in engine.plan.part_ids},
                        {p: cell.buffer_seconds(p) for p in engine.plan.part_ids}]
        # The action without its reasons, on the machine form of the state, where the policy offers it.
        self._choose_at = getattr(self.policy, "choose_at", None)
        self.budgeted = config.decision_budget is not None
        # A policy may say which situations it decides alike: fewer distinct keys, more cache hits.
        # (Only on plans small enough for situations to recur; on large ones the key is pure overhead.)
        make_key = getattr(self.policy, "decision_key", None)
        use_key = make_key is not None and self.cache is not None and engine.n_units <= ALIKE_KEY_UNITS
        self._key = make_key(engine, self.capacity) if use_key else None
        self._canonical: dict = {}
        self._looked = self._decided = 0  # looks and decisions made, while there is a cache
        self.limit = config.step_limit

    def _decide(self, mask, cons, installed, buffer, look) -> Action:
        if self.budgeted:
            # As the sequencer does: memos grow but are never evicted, doubled or restarted within a
            # budgeted decision (doubling a compiled memo of 800,000 entries took one of 50 ms to 163);
            # that upkeep runs between decisions, outside their budget.
            with self.engine.deciding():
                action = self._decide_now(mask, cons, installed, buffer, look)
            self.engine.maintain()
            return action
        return self._decide_now(mask, cons, installed, buffer, look)

    def _decide_now(self, mask, cons, installed, buffer, look) -> Action:
        if self._choose_at is not None:
            free = math.inf if self.capacity is None else self.capacity - len(buffer)
            return self._choose_at(self.engine, mask, cons, buffer, free, look)
        state = State._make(Schedule.at(self.engine, mask, cons, tuple(installed)), buffer, self.capacity)
        return self.policy.decide(state, look).action

    def _fill(self, mask, cons, installed, buffer, look) -> tuple:
        """The cached decision for a situation not seen yet, as ``(op, part, next (mask, strategies) or None)``:
        an install carries the state it leads to, so a cache hit needs no second look-up."""
        keyfn = self._key
        if keyfn is not None:  # an equivalent situation may have been decided already
            alike = keyfn(mask, cons, buffer, look)
            code = self._canonical.get(alike)
            if code is None:
                code = self._canonical[alike] = _code(self._decide(mask, cons, installed, buffer, look))
                self._decided += 1
        else:
            code = _code(self._decide(mask, cons, installed, buffer, look))
            self._decided += 1
        op, part = code
        entry = (op, part, self._install(mask, cons, part) if op < 2 else None)
        cache = self.cache
        if len(cache) >= DECISION_CACHE_LIMIT:  # bounded memory on large plans
            cache.clear()
        cache[(mask, cons, buffer, look)] = entry
        return entry

    def _review_cache(self, looks: int) -> None:
        """Drop the decision cache if it answers too few looks to pay for its keys and memory
        (on large plans situations rarely recur: every look is then a new key)."""
        self._looked += looks
        if self._looked >= CACHE_PROBE_LOOKS and self._decided > (1 - CACHE_MIN_HITS) * self._looked:
            self.cache = None
            self._key = None
            self._canonical = {}

    def _install(self, mask, cons, part):
        key = (mask, cons, part)
        t = self.transitions.get(key)
        if t is None:
            engine = self.engine
            u = engine.next_unit(mask, self.index[part])
            t = (mask | 1 << u, engine.consistent_after(mask, cons, u))
            if len(self.transitions) >= DECISION_CACHE_LIMIT:  # bounded memory, as for decisions
                self.transitions.clear()
            self.transitions[key] = t
        return t

    def run(self, trial: int) -> TrialResult:
        world = self.world
        world.reset(self.units, random.Random(trial_seed(self.config.seed, trial, 0)))
        start = getattr(self.policy, "start", None)
        if start is not None:
            start(random.Random(trial_seed(self.config.seed, trial, 1)))
        engine, cache, move, costs = self.engine, self.cache, self.move, self.costs
        transitions = self.transitions
        look_at, take = world.look, world.take
        full = engine.full
        mask, cons, buffer, installed = 0, engine.all_strategies, (), []
        motions = buffer_moves = shakes = looks = peak = 0
        t = secs = 0.0
        seconds = self.seconds
        index = self.index
        limit = self.limit
        while mask != full:
            if looks >= limit:
                break
            look = look_at()
            looks += 1
            if len(look) == 2:
                a, b = look
                if index[a] > index[b]:
                    look = (b, a)
            elif len(look) > 2:
                look = tuple(sorted(look, key=index.__getitem__))
            if cache is not None:
                code = cache.get((mask, cons, buffer, look))
                if code is None:
                    code = self._fill(mask, cons, installed, buffer, look)
                op, part, nxt = code
            else:
                op, part = _code(self._decide(mask, cons, installed, buffer, look))
                nxt = None
            if op < 2:  # install from the bin (0) / from the buffer (1)
                if op:
                    i = buffer.index(part)
                    buffer = buffer[:i] + buffer[i + 1:]
                else:
                    take(part)
                if nxt is None:
                    nxt = transitions.get((mask, cons, part)) or self._install(mask, cons, part)
                mask, cons = nxt
                installed.append(part)
                motions += 1
                t += move[part]
                secs += seconds[op][part]
            elif op == 2:  # buffer
                take(part)
                buffer = buffer + (part,)
                motions += 1
                buffer_moves += 1
                t += move[part]
                secs += seconds[2][part]
                if len(buffer) > peak:
                    peak = len(buffer)
            elif op == 3:
                world.shake()
                shakes += 1
                t += costs.shake
                secs += self.config.cell.shake
            else:  # done before completion cannot happen; guard against a policy bug
                raise RuntimeError(f"policy {self.strategy} said 'done' before the assembly was complete")
        t += looks * costs.look
        secs += looks * self.config.cell.camera
        if cache is not None:
            self._review_cache(looks)
        return TrialResult(self.strategy, trial, motions, buffer_moves, shakes, looks, peak, t, secs, mask == full)


_OPS = {"buffer": 2, "shake": 3}


def _code(action: Action) -> tuple[int, str | None]:
    """An action in the compact form the trial loop caches."""
    if action.kind == "install":
        return (1 if action.source == "buffer" else 0, action.part)
    return (_OPS.get(action.kind, 4), action.part)


def trial_seed(seed: int, trial: int, stream: int) -> int:
    """The integer seed of one random stream of one trial: independent of workers and chunking."""
    return ((abs(seed) * 2 + (seed < 0)) << 48) | (trial << 4) | stream


def run_trial_with_sequencer(strategy: str, engine: OrderEngine, config: StudyConfig, prepared: Prepared,
                             trial: int) -> TrialResult:
    """The same trial played through the full :class:`~opportune.sequencer.Sequencer` (slow; for checking)."""
    from opportune.sequencer import Sequencer

    policy = make_policy(strategy, engine, config, prepared)
    world = _world(config, prepared, strategy)
    units = [p.id for p in engine.plan.parts for _ in range(p.quantity)]
    world.reset(units, random.Random(trial_seed(config.seed, trial, 0)))
    if hasattr(policy, "start"):
        policy.start(random.Random(trial_seed(config.seed, trial, 1)))
    seq = Sequencer(engine, policy, buffer_capacity=capacity_for(strategy, config))
    index = {p: i for i, p in enumerate(engine.plan.part_ids)}
    r = TrialResult(strategy, trial, 0, 0, 0, 0, 0, 0.0)
    while not seq.state.is_complete and r.looks < config.step_limit:
        look = tuple(sorted(world.look(), key=index.__getitem__))
        r.looks += 1
        action = seq.decide(look).action
        if action.kind in ("install", "buffer"):
            if action.source != "buffer":
                world.take(action.part)
            r.motions += 1
            r.time += config.costs.move(action.part)
            r.buffer_moves += action.kind == "buffer"
            r.cycle_seconds += (config.cell.buffer_seconds(action.part) if action.kind == "buffer"
                          else config.cell.install_seconds(action.part, action.source or "bin"))
        elif action.kind == "shake":
            world.shake()
            r.shakes += 1
            r.time += config.costs.shake
            r.cycle_seconds += config.cell.shake
        seq.report("success")
        r.buffer_peak = max(r.buffer_peak, len(seq.state.buffer))
    r.time += r.looks * config.costs.look
    r.cycle_seconds += r.looks * config.cell.camera
    r.complete = seq.state.is_complete
    return r


# ---------------------------------------------------------------- many trials, many workers

_WORKER_CACHE: dict = {}


def run_chunk(config: StudyConfig, prepared: Prepared, strategy: str, start: int, stop: int) -> list[tuple]:
    """Trials ``start .. stop-1`` of one strategy (a unit of work for a process or a Dask worker)."""
    study = hash_config(config)
    key = (study, strategy)
    runner = _WORKER_CACHE.get(key)
    if runner is None:
        engine_key = (study, "engine")
        engine = _WORKER_CACHE.get(engine_key)
        if engine is None:
            engine = _WORKER_CACHE[engine_key] = OrderEngine(config.plan)
        if strategy in COUNTING_STRATEGIES and config.decision_budget is not None:
            # As prepare() did in the parent: count the first state before the first decision.  A budgeted
            # decision on a cold engine cannot, so the first trials would estimate what a warm engine
            # counts, and learn that exact counts are slow (ARC111: 0.6 s a trial instead of 0.3).
            Schedule(engine).warm_up(config.count_time_limit)
        runner = _WORKER_CACHE[key] = TrialRunner(strategy, engine, config, prepared)
    # Trials make no reference cycles, but they allocate millions of small tuples, and the cyclic
    # collector would walk the ever-growing caches each time: pause it for the chunk.
    paused = gc.isenabled()
    gc.disable()
    try:
        return [runner.run(i).row() for i in range(start, stop)]
    finally:
        if paused:
            gc.enable()


def plan_sha256(plan: Plan) -> str:
    """The SHA-256 of a plan's content (its file-schema document, keys sorted): ``results.json``'s
    ``provenance.plan_sha256``, checked by ``simulate --from``."""
    import hashlib
    import json

    return hashlib.sha256(json.dumps(plan.to_dict(), sort_keys=True, default=str).encode()).hexdigest()


def hash_config(config: StudyConfig) -> str:
    import hashlib
    import json

    doc = {"plan": config.plan.to_dict(), "bin": config.bin, "visible": config.visible,
           "capacity": config.buffer_capacity, "costs": config.costs.to_dict(), "seed": config.seed,
           "training": config.training_runs}
    if config.decision_budget is not None:   # another policy (an unbudgeted study keeps its hash)
        doc["budget"] = config.decision_budget
    if config.cell != CellModel():   # another cell (a study in the default cell keeps its hash)
        doc["cell"] = config.cell.to_dict()
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def chunks(trials: int, size: int) -> list[tuple[int, int]]:
    return [(a, min(a + size, trials)) for a in range(0, trials, size)]


@dataclass
class StudyResult:
    """A study's trials per strategy, and what the study cost.

    Made by :func:`run_study`.

    Parameters
    ----------
    config : StudyConfig
        The study.
    prepared : Prepared
        Its preparation (:func:`prepare`).
    trials : dict of str to list of TrialResult
        Each strategy's trials, by trial number.
    cpu_seconds : dict of str to float
        CPU seconds of each strategy's trials summed over every worker that ran them (the same
        measure on 1 worker or 20).
    interrupted : bool, default False
        Ctrl-C stopped the study: the trials are those that finished.
    wall_seconds : float, default 0.0
        Elapsed seconds of the whole study, preparation (the optimum, quantify's training) and
        trials together.
    workers : int or None, default 1
        Local worker processes (``None``: on a Dask cluster).

    Examples
    --------
    >>> from opportune import load_plan
    >>> result = run_study(StudyConfig(load_plan("example:gearbox"), strategies=("paper", "shake"), trials=20),
    ...                    workers=1)
    >>> sorted(result.trials), len(result.trials["shake"]), result.interrupted
    (['paper', 'shake'], 20, False)
    """

    config: StudyConfig
    prepared: Prepared
    trials: dict[str, list[TrialResult]]
    cpu_seconds: dict[str, float]
    interrupted: bool = False
    wall_seconds: float = 0.0
    workers: int | None = 1   # local worker processes (None: on a Dask cluster)

    @property
    def seconds(self) -> dict[str, float]:
        """The CPU seconds per strategy (:attr:`cpu_seconds`), under the name earlier versions used."""
        return self.cpu_seconds

    def to_frame(self):
        """The trials as a pandas DataFrame, one row per trial of each strategy (the rows of ``trials.csv``).

        Columns: ``strategy``, ``trial``, the costs (``motions``, ``buffer_moves``, ``shakes``,
        ``looks``, ``buffer_peak``, ``time``, ``cycle_seconds``) and ``complete``; trial ``i`` of every
        strategy saw the same bin, so ``df.pivot(index="trial", columns="strategy", values="time")``
        pairs them.

        Returns
        -------
        pandas.DataFrame
            The trials, ``strategy`` as a category.

        Raises
        ------
        ImportError
            If pandas is not installed (``pip install pandas``).

        Examples
        --------
        >>> from opportune.datasets import example_path
        >>> from opportune.formats import load_plan
        >>> config = StudyConfig(load_plan(example_path("gearbox")), strategies=("paper", "random"), trials=100)
        >>> df = run_study(config, workers=1).to_frame()
        >>> len(df), sorted(df["strategy"].unique())
        (200, ['paper', 'random'])
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("StudyResult.to_frame needs pandas: pip install pandas") from None
        columns = ["strategy", "trial", *METRICS, "complete"]
        rows = [(name, t.trial, *(getattr(t, m) for m in METRICS), t.complete)
                for name, trials in self.trials.items() for t in trials]
        frame = pd.DataFrame(rows, columns=columns)
        return frame.astype({"strategy": "category"}) if rows else frame


def run_study(config: StudyConfig, *, workers: int | None = None, dask_address: str | None = None,
              chunk_size: int | None = None, progress: Callable[[str, int], None] | None = None,
              prepared: Prepared | None = None) -> StudyResult:
    """Run every strategy of ``config``: locally (``workers`` processes; 1 = in this process) or on Dask.

    The numbers depend only on the configuration, not on the workers or the chunks: trial *i*
    draws its bin from its own seeded stream.  Ctrl-C stops cleanly: the result holds the trials
    that finished, with ``interrupted`` set.

    Parameters
    ----------
    config : StudyConfig
        The study.
    workers : int, optional
        Local worker processes (``None``: one per core this process may use; 1: in this process).
    dask_address : str, optional
        A Dask scheduler's address (``tcp://host:8786``): run the chunks there instead.
    chunk_size : int, optional
        Trials per chunk handed to a worker (``None``: about four chunks per worker).
    progress : callable, optional
        Called as ``progress(strategy, n)`` when a chunk of ``n`` trials finishes.
    prepared : Prepared, optional
        The study's :func:`prepare`, made beforehand (its time counts in ``wall_seconds``).

    Returns
    -------
    StudyResult
        The trials of every strategy, and what they cost.

    Raises
    ------
    StudyError
        If the configuration is not valid (:meth:`StudyConfig.validate`), or a strategy cannot run on
        the plan (:class:`StrategyUnavailable`, from :func:`prepare`).

    Examples
    --------
    >>> from opportune import load_plan
    >>> config = StudyConfig(load_plan("example:gearbox"), strategies=("paper", "shake"), trials=50, seed=1)
    >>> result = run_study(config, workers=1)
    >>> {s: sum(t.motions for t in trials) / len(trials) for s, trials in result.trials.items()}
    {'paper': 13.64, 'shake': 10.0}
    """
    config.validate()
    began = _time.perf_counter()
    # The engine the trials use here and in forked workers (run_chunk finds it in the cache): what
    # prepare() counts with it, they need not count again.
    engine_key = (hash_config(config), "engine")
    engine = _WORKER_CACHE.get(engine_key) or _WORKER_CACHE.setdefault(engine_key, OrderEngine(config.plan))
    if prepared is None:
        prepared = prepare(config, engine)
    else:
        began -= prepared.seconds   # prepared beforehand (the command line does): still part of the study
    workers = workers if workers is not None else _default_workers()
    # about four chunks per worker, so that the last ones end together (but not so small that handing them
    # out costs more than they take)
    size = chunk_size or max(10, min(2000, config.trials // max(1, 4 * workers)))
    results: dict[str, list[TrialResult]] = {s: [] for s in config.strategies}
    seconds: dict[str, float] = {}
    interrupted = False
    jobs = [(s, a, b) for s in config.strategies for a, b in chunks(config.trials, size)]
    try:
        if dask_address:
            _run_dask(dask_address, config, prepared, jobs, results, seconds, progress)
        elif workers <= 1:
            for s, a, b in jobs:
                _collect(s, timed_chunk(config, prepared, s, a, b), results, seconds, progress)
        else:
            _run_processes(workers, config, prepared, jobs, results, seconds, progress)
    except KeyboardInterrupt:
        interrupted = True
    for s in results:
        results[s].sort(key=lambda r: r.trial)
    return StudyResult(config, prepared, results, seconds, interrupted,
                       wall_seconds=_time.perf_counter() - began, workers=None if dask_address else max(1, workers))


def _default_workers() -> int:
    import os

    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def timed_chunk(config: StudyConfig, prepared: Prepared, strategy: str, start: int, stop: int) -> tuple[list, float]:
    """:func:`run_chunk` and the CPU seconds it took in the thread that ran it (a Dask worker's
    other threads and this process's other work are not counted)."""
    cpu = _time.thread_time()
    rows = run_chunk(config, prepared, strategy, start, stop)
    return rows, _time.thread_time() - cpu


def _collect(s, timed, results, seconds, progress):
    rows, cpu = timed
    results[s].extend(TrialResult(*r) for r in rows)
    seconds[s] = seconds.get(s, 0.0) + cpu   # summed over chunks, whichever worker ran them
    if progress:
        progress(s, len(rows))


_FORKED_STUDY = None


def _run_forked_chunk(strategy: str, start: int, stop: int) -> tuple[list, float]:
    config, prepared = _FORKED_STUDY
    return timed_chunk(config, prepared, strategy, start, stop)


def _run_processes(workers, config, prepared, jobs, results, seconds, progress):
    """The chunks on a pool of ``workers`` processes, each handed out as a worker frees up.

    No chunk runs here before the pool starts: each worker's caches warm up on its own first
    trials about as fast as they would on a warm-up run here, while a warm-up run here would
    leave every other core idle for its whole length.
    """
    import multiprocessing as mp

    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    global _FORKED_STUDY
    # Forked workers inherit the study (no pickling of the plan or the optimum's table per chunk).
    _FORKED_STUDY = (config, prepared) if ctx is not None else None
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
    try:
        pending = {}
        for s, a, b in jobs:
            if ctx is not None:
                fut = pool.submit(_run_forked_chunk, s, a, b)
            else:
                fut = pool.submit(timed_chunk, config, prepared, s, a, b)
            pending[fut] = s
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                s = pending.pop(fut)
                _collect(s, fut.result(), results, seconds, progress)
    except KeyboardInterrupt:
        for fut in list(pending):
            fut.cancel()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def _run_dask(address, config, prepared, jobs, results, seconds, progress):
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise StudyError("--dask needs Dask distributed: pip install 'opportune[scale]'") from None
    try:
        client = address if not isinstance(address, str) else Client(address, timeout="10s")
    except OSError as exc:
        raise StudyError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
    own = isinstance(address, str)
    try:
        cfg = client.scatter(config, broadcast=True)
        prep = client.scatter(prepared, broadcast=True)
        futures = {}
        for s, a, b in jobs:
            futures[client.submit(timed_chunk, cfg, prep, s, a, b, pure=False)] = s
        for fut in as_completed(list(futures)):
            _collect(futures[fut], fut.result(), results, seconds, progress)
    finally:
        if own:
            client.close()
