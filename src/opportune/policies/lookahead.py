"""The look-ahead policy: the optimum's action where its programme fits, else the exact optimum of a
frontier window (:mod:`~opportune.policies.window` in a uniform bin, :mod:`~opportune.policies.pile_window`
in the pile, :mod:`~opportune.policies.weighted_window` in a weighted bin), or where none serves one step
of policy improvement over a base rule (default :class:`~opportune.policies.variants.Slack`), within a
decision budget if it has one.  See :mod:`~opportune.policies.variants` for the rules it builds on.
"""

from __future__ import annotations

import time
from dataclasses import replace

from opportune.engine.deadline import BudgetExceeded, Deadline, as_deadline
from opportune.engine.tuning import (LOOKAHEAD_BASE_SHARE, LOOKAHEAD_COMPILED_STATES, LOOKAHEAD_LISTING_PARTS,
                                     LOOKAHEAD_PROGRAMME_SHARE, LOOKAHEAD_STEP_UNITS, LOOKAHEAD_WINDOW_SHARE)
from opportune.policies.base import (
    DONE,
    SHAKE,
    Action,
    DecidesOnMasks,
    Decision,
    pause_collector,
    resume_collector,
)
from opportune.policies.evaluate import OutOfTime, PolicyEvaluator
from opportune.policies.look import LookState
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.optimal import (
    COMPILED_WEIGHTED_LOOKS,
    OptimalTooLarge,
    compiled_optimal_available,
    optimal_solver,
    optimum_bytes,
    optimum_engine,
    same_action,
    ways_table_bytes,
)
from opportune.policies.pile_window import PileWindow, pile_window_available
from opportune.policies.variants import Slack
from opportune.policies.weighted_window import WeightedWindow, weighted_window_available
from opportune.policies.window import FrontierWindow, window_available

__all__ = ["Lookahead", "programme_bytes"]

# The look-ahead's programmes are kept on their engine (OrderEngine.kept, freed with it), by settings:
# see Lookahead._values.  Optima prepared as per-plan work (Lookahead.prepare): those under way, and
# those finished, which a look-ahead with a budget takes up at its next decision.
_KEPT = "lookahead programmes"
_PREPARING = "lookahead optima under way"
_READY = "lookahead optima ready"


class _Preparation:
    """An optimum under way (:meth:`Lookahead.prepare`): its listing, then its solver; or why it does not fit."""

    def __init__(self, listing, cap: int):
        self.listing, self.cap = listing, cap
        self.solver = None
        self.refusal: str | None = None


def programme_bytes(engine) -> int:
    """The bytes of the look-ahead programmes kept on ``engine`` (Python values and look caches; a
    compiled table's bytes are granted by :meth:`~opportune.engine.schedule.OrderEngine.reserve_programme`
    and counted in the engine's own :meth:`~opportune.engine.schedule.OrderEngine.nbytes`).  O(programmes).

    Parameters
    ----------
    engine : OrderEngine
        The engine the programmes were built on.

    Returns
    -------
    int
        Estimated bytes (0 where no look-ahead has decided on it).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> programme_bytes(OrderEngine(make_plan(["a"], {})))
    0
    """
    from opportune.engine.memory import nbytes

    total = 0
    for ev in list(engine.kept.get(_KEPT, {}).values()):
        total += nbytes(getattr(ev, "_values", {}))
        looks = getattr(ev, "_looks", None)
        if looks is not None and hasattr(looks, "cache_info"):
            total += 400 * looks.cache_info().currsize     # a look distribution: a tuple of a few tuples
    return total


class Lookahead(DecidesOnMasks):
    """The optimal action where the optimum's programme fits, else the best action of the frontier window's
    exact optimum (the next parts of the plan, the rest lumped; ``base`` where no window fits its states or
    time): :class:`~opportune.policies.window.FrontierWindow` in a uniform bin,
    :class:`~opportune.policies.pile_window.PileWindow` in the pile,
    :class:`~opportune.policies.weighted_window.WeightedWindow` in a weighted bin; where no window serves
    (no compiled core), one step of policy improvement over ``base`` (default :class:`Slack`), and on plans
    too large for that, the base's action.

    The scores are expected costs in the world of ``solver_settings``.  ``max_states`` bounds either
    programme: the optimum's (:class:`~opportune.policies.optimal.OptimalSolver`, every state any policy
    reaches, counted before it starts by :func:`~opportune.policies.states.estimate_states`) is used when
    it holds at most that many states, else the base policy's (the states the base reaches, fewer: its
    values after each action make the improvement step).  ``optimal=False`` (or setting :attr:`optimal`;
    ``opportune evaluate --without-optimum``) switches its exact optimum off, so that it decides by its
    fallback: the window of its bin.  How near the optimum the windows and the step come, against the rules
    alone, is measured in docs/decisions.md (``benchmarks/bench_fallback.py``).
    The window's work is counted (``self.window.work``), at most
    :data:`~opportune.policies.window.WINDOW_STATES` states a size tried; with a budget it also stops at
    :attr:`WINDOW_SHARE` of it and the base decides within the rest.  The pile bin likewise, with its own programmes
    (:class:`~opportune.policies.pile.PileSolver`: the window is part of the state).  In either bin
    the optimum's programme is the compiled one where the core is built
    (:class:`~opportune.policies.optimal.CompiledOptimalSolver`,
    :class:`~opportune.policies.pile.CompiledPileSolver`), used up to :attr:`COMPILED_STATES` states
    and within the bytes the engine grants, whatever the plan's units; the step over the base is tried
    on plans of up to :attr:`STEP_UNITS` units.

    On a plan written as ways (:attr:`~opportune.planning.plan.Plan.ways`) the optimum's programmes, compiled
    too, take the ways table and decide exactly which sets have a completion; where the optimum does not
    fit, no frontier window serves (the windows read the strategies' orders): its default base is then the
    paper's rule (:class:`~opportune.policies.opportunistic.Opportunistic`, through the answering layer),
    the step over it deciding on plans of up to :attr:`STEP_UNITS` units and the rule itself beyond, as
    :attr:`deciding_rule` and the decisions say (measured against the optimum: docs/decisions.md).

    Parameters
    ----------
    base : Policy, optional
        The rule it improves on and falls back to (default :class:`~opportune.policies.variants.Slack`).
    budget : float, optional
        Seconds a decision may take (None: exact, with no time limit; the decisions are then the same on
        every machine).  The programme gets most of it at each decision, resuming where it stopped; a
        decision it does not finish in time is the base's, within the rest.
    max_states : int
        States either programme may hold (see above).
    optimal : bool
        Whether its exact optimum may decide where it fits (False: its fallback alone).
    **solver_settings
        The world it acts in: ``visible``, ``capacity``, ``costs``, ``weights`` (see
        :class:`~opportune.policies.evaluate.PolicyEvaluator`), and ``bin`` (``"pile"`` for the pile's
        programmes; any other value or none: the uniform or weighted bin).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.sequencer import Sequencer
    >>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
    >>> d = Sequencer(plan, Lookahead(visible=1, capacity=1), buffer_capacity=1).decide(["c"])
    >>> d.action, d.note
    (Action(kind='buffer', part='c', source=None), "expected remaining cost 4.0000 (the optimum's)")
    >>> without = Lookahead(visible=1, capacity=1, optimal=False)      # the frontier window decides
    >>> print(Sequencer(plan, without, buffer_capacity=1).decide(["c"]).rule)
    by its frontier window, because its exact optimum is switched off: the action of least expected cost ...
    >>> without.window.work["windows"]
    1
    """

    name = "lookahead"
    rule = "the action with the least expected cost of finishing by the base rule"
    #: What the decisions say where the optimum's programme decides.
    OPTIMAL_RULE = "the action with the least expected cost of finishing (the exact optimum)"
    decision_key = None     # it decides on the whole state (the buffer's contents too): no alike situations
    #: The compiled optimum (of the uniform or weighted bin, :class:`~opportune.policies.optimal.CompiledOptimalSolver`,
    #: on the plan with its interchangeable parts merged, or of the pile, :class:`~opportune.policies.pile.CompiledPileSolver`)
    #: decides on plans of up to this many states (counted before it starts; ``max_states`` if larger; in a weighted
    #: bin fewer, see :meth:`_optimum_cap`), whatever their units, where its bytes (known before it starts too: at
    #: most 64 a state and the pairs it interns, so about 350 MB at most, and a weighted bin's look cache)
    #: are granted by the engine (:meth:`~opportune.engine.schedule.OrderEngine.reserve_programme`, within
    #: half its ``memory_limit``); its table is reserved for the count at once.  Without a budget it is
    #: solved whole in the first decision on the plan (a warm-up: about a million states a second) and
    #: shared by the look-aheads of the same settings; with one, each decision goes on with it within its
    #: share of the budget (the clock is read at every new state).  The Python programme (no compiled
    #: core) is held to ``max_states``.
    COMPILED_STATES = LOOKAHEAD_COMPILED_STATES
    #: Where the optimum does not fit and no window serves (no compiled core), plans
    #: of more units than this decide as the base does: the step over the base evaluates the base look by
    #: look in Python (every look of every state asks the base rule), hours on a 45-part plan.  The optimum
    #: itself is never refused by units, only by its states and bytes.
    STEP_UNITS = LOOKAHEAD_STEP_UNITS
    #: With a budget, the share of it the frontier window may take (its programme is stopped there and the
    #: base decides within the rest, :attr:`fallback`'s quarter): its states are capped
    #: (:data:`~opportune.policies.window.WINDOW_STATES`), so this binds only on a very slow machine.
    WINDOW_SHARE = LOOKAHEAD_WINDOW_SHARE
    #: Without a budget, the moment (a :class:`~opportune.engine.deadline.Deadline`) past which its exact
    #: programme stops and raises :class:`~opportune.policies.optimal.OutOfTime` (what it finished stays):
    #: a caller's own deadline, e.g. ``evaluate --time-limit``.  None: none.
    deadline = None
    #: What the decisions say where the step over the paper's rule decides on a plan written as ways.
    WAYS_RULE = ("the action with the least expected cost of finishing by the paper's rule (a plan written as "
                 "ways: the frontier window reads partial orders)")
    #: Why the optimum did not decide when :attr:`optimal` is False (the decisions quote it).
    SWITCHED_OFF = "its exact optimum is switched off"

    def __init__(self, base=None, *, budget: float | None = None, max_states: int = 200_000, optimal: bool = True,
                 **solver_settings):
        # With a budget, the programme gets most of it at each decision, resuming where it stopped; a
        # decision it does not finish in time is the base's (itself within the rest of the budget).
        self.lookahead_budget = budget
        self.deterministic = budget is None
        self.base = base if base is not None else Slack()      # exact: the programme evaluates it
        # the base within what the programme leaves of the budget; on a plan too large for the programme,
        # within the whole budget (nothing else runs then)
        self.fallback = self.base if budget is None else Slack(budget=budget * LOOKAHEAD_BASE_SHARE)
        self.fallback_alone = self.base if budget is None else Slack(budget=budget)
        # the bases by the plan's kind (written as ways or not): see _suit
        self._bases = {False: (self.base, self.fallback, self.fallback_alone)}
        if base is not None:
            self._bases[True] = self._bases[False]      # a base given is the base on every plan
        self._on_ways = False
        #: The frontier window that decides where the optimum does not fit, in a uniform bin (its ``work``
        #: counts its windows and states); its base is the fallback within what it leaves of the budget.
        self.window = None
        self.max_states = max_states
        # the pile bin has its own programme (policies/pile.py): the window is part of the state
        self.pile = solver_settings.pop("bin", "uniform") == "pile"
        if self.pile:
            solver_settings.pop("weights", None)
        self.settings = solver_settings
        window = PileWindow if self.pile else FrontierWindow
        self.window = window(self.fallback, visible=solver_settings.get("visible", 2),
                             capacity=solver_settings.get("capacity"), costs=solver_settings.get("costs"))
        self.optimal = optimal
        self._optimum_states = 0        # the optimum's states, counted before it starts (where it fits)
        #: Why the optimum's programme did not decide (states or bytes, before it started), or None.
        self.refusal: str | None = None
        self.last_cost: float | None = None

    def _suit(self, engine) -> None:
        """The base for the plan's kind: on a plan written as ways, unless a base was given, the paper's rule
        (:class:`~opportune.policies.opportunistic.Opportunistic`, through the answering layer; the frontier
        windows read the strategies' orders, which such a plan does not have).  Switching kind drops the
        programme chosen so far.  O(1)."""
        ways = bool(engine.plan.is_ways)
        if ways == self._on_ways:
            return
        if ways not in self._bases:
            budget = self.lookahead_budget
            paper = Opportunistic()
            self._bases[True] = (paper, paper if budget is None else Opportunistic(budget=budget * LOOKAHEAD_BASE_SHARE),
                                 paper if budget is None else Opportunistic(budget=budget))
        self.base, self.fallback, self.fallback_alone = self._bases[ways]
        self._on_ways = ways
        self._evaluator, self._too_large, self._by_window = None, False, False

    @property
    def optimal(self) -> bool:
        """Whether its exact optimum may decide (where it fits); False: it decides by its fallback alone.
        Setting it drops the programme chosen so far: the next decision chooses again."""
        return self._optimal

    @optimal.setter
    def optimal(self, value: bool) -> None:
        self._optimal = bool(value)
        self._evaluator, self._too_large, self._by_window = None, False, False

    @property
    def uses_buffer_order(self) -> bool:
        """As its base: the scores are the base's values, on states that keep the buffer's order if the base uses it."""
        return bool(getattr(self.base, "uses_buffer_order", False))

    def buffer_ties_at(self, engine, mask: int, consistent: int):
        """The pairs of parts whose order in the buffer can decide an action at a state: the base's (the
        look-ahead's own tie-breaks are by kind and declaration order, not by the buffer's; its scores
        differ only through the base's values).

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.

        Returns
        -------
        list of (int, int) or None
            Declaration indices, the lower first; None (a base that does not say): any pair's order may decide.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> Lookahead().buffer_ties_at(engine, 0, 1)
        [(0, 1)]
        """
        self._suit(engine)
        ties = getattr(self.base, "buffer_ties_at", None)
        return None if ties is None else ties(engine, mask, consistent)

    def _values(self, engine):
        if self._evaluator is None or self._evaluator.engine is not engine:
            # One programme per plan and world, shared by every look-ahead of the same settings (the service
            # starts a policy per run: each would otherwise redo the whole programme).  Callers that share
            # an engine already serialise its use, which covers its evaluator too.
            key = self._share_key()
            shared = engine.kept.setdefault(_KEPT, {}) if key is not None else {}
            ev = shared.get(key)
            if ev is None:
                # the optimum's values where they fit (a policy of None), else the base's
                base = None if self._optimum_fits(engine) else self.base
                if base is not None and self._window_serves(engine):
                    self._by_window = True
                    return None         # the frontier window decides
                if base is not None and engine.n_units > self.STEP_UNITS:
                    return None         # the step over the base is out of reach: the base decides
                if base is None:
                    ev = self._optimum_solver(engine)
                elif self.pile:
                    from opportune.policies.pile import PileSolver

                    ev = PileSolver(engine, base, max_states=self.max_states, **self.settings)
                else:
                    ev = PolicyEvaluator(engine, base, max_states=self.max_states, **self.settings)
                if base is None:
                    ev.reserve(self._optimum_states)    # compiled: no table doubling inside a decision
                if key is not None:
                    shared[key] = ev
            self._evaluator = ev
            self._too_large = False
        return self._evaluator

    def _optimum_solver(self, engine):
        """The optimum's programme of this bin and settings on ``engine``, not started."""
        if self.pile:
            from opportune.policies.pile import pile_solver

            return pile_solver(engine, max_states=self._optimum_cap(engine), **self.settings)
        return optimal_solver(engine, max_states=self._optimum_cap(engine), merge=self._merges(engine), **self.settings)

    def _window_serves(self, engine) -> bool:
        """Whether the frontier window decides where the optimum does not fit: a uniform bin and the
        compiled core (:func:`~opportune.policies.window.window_available`), or the pile or a weighted bin and
        the compiled core (:func:`~opportune.policies.pile_window.pile_window_available`,
        :func:`~opportune.policies.weighted_window.weighted_window_available`; :attr:`window` becomes the
        weighted bin's window on a plan whose weights differ).  O(parts)."""
        if engine.plan.is_ways:
            return False        # the windows read the strategies' orders: the base decides (see _suit)
        if self.pile:
            return pile_window_available(engine)
        visible = self.settings.get("visible", 2)
        if self._weighted(engine):
            # the weighted bin's window (its looks enumerated), in place of the uniform bin's
            if not isinstance(self.window, WeightedWindow):
                self.window = WeightedWindow(self.fallback, visible=visible, capacity=self.settings.get("capacity"),
                                             costs=self.settings.get("costs"), weights=self.settings.get("weights"))
            return weighted_window_available(engine, visible)
        return window_available(engine, self.settings.get("weights"))

    def _compiled(self, engine) -> bool:
        """Whether the optimum's programme for this plan and bin is the compiled one.  O(parts)."""
        if self.pile:
            from opportune.policies.pile import compiled_pile_available

            return compiled_pile_available(engine)
        return compiled_optimal_available(self._sized(engine), self.settings.get("weights"),
                                          visible=self.settings.get("visible", 2))

    def _optimum_cap(self, engine) -> int:
        """The optimum's state cap: :attr:`COMPILED_STATES` (or ``max_states`` if larger) for a compiled
        optimum, else ``max_states``; in a weighted bin, whose compiled programme enumerates a bin's looks
        at every state, no more states than :data:`~opportune.policies.optimal.COMPILED_WEIGHTED_LOOKS`
        over the looks at the start (nor fewer than ``max_states``).  O(parts × visible)."""
        if not self._compiled(engine):
            return self.max_states
        cap = max(self.max_states, self.COMPILED_STATES)
        if self._weighted(engine):
            from opportune.policies.states import looks_at_start

            looks = looks_at_start(self._sized(engine), self.settings.get("visible", 2))
            cap = max(self.max_states, min(cap, COMPILED_WEIGHTED_LOOKS // max(1, looks)))
        return cap

    def _sized(self, engine):
        """The engine whose states the optimum's programme stores: the plan's with its interchangeable
        parts merged (:func:`~opportune.policies.optimal.optimum_engine`) where :meth:`_merges`, else the plan's."""
        if not self._merges(engine):
            return engine
        return optimum_engine(engine, self.settings.get("costs"), self.settings.get("weights"))

    def _merges(self, engine) -> bool:
        """Whether its optimum merges interchangeable parts: not in the pile, and with a budget only on plans
        the compiled programme takes (at most 64 units): merging builds the merged plan's orders, work that
        grows with the plan, inside the first budgeted decision.  O(1)."""
        return not self.pile and (self.lookahead_budget is None or engine.n_units <= 64)

    def _weighted(self, engine) -> bool:
        """Whether the bin is weighted with weights that differ (not the pile).  O(parts)."""
        weights = self.settings.get("weights")
        return (not self.pile and bool(weights)
                and len({float(weights.get(p.id, 1.0)) for p in engine.plan.parts}) > 1)

    def _optimum_bytes(self, engine, estimate) -> int:
        """The bytes the optimum's programme holds, from its state count: the compiled uniform table and
        its pairs (:func:`~opportune.policies.optimal.optimum_bytes`), the compiled pile's
        :data:`~opportune.policies.pile.COMPILED_BYTES_PER_STATE` a value, or the Python programme's
        :data:`~opportune.policies.states.BYTES_PER_STATE`; on a plan written as ways, the compiled programme's
        table of sets decided live or dead too (:func:`~opportune.policies.optimal.ways_table_bytes`).
        O(log states)."""
        compiled = self._compiled(engine)
        ways = compiled and engine.plan.is_ways     # the compiled programme's table of sets decided live or dead
        if self.pile and compiled:
            from opportune.policies.pile import COMPILED_BYTES_PER_STATE

            return COMPILED_BYTES_PER_STATE * estimate.states + (ways_table_bytes(estimate.states) if ways else 0)
        looks = (estimate.looks, min(self.settings.get("visible", 2), engine.n_units)) if self._weighted(engine) else None
        return optimum_bytes(estimate.states, estimate.keys, compiled=compiled and not self.pile, weighted_looks=looks,
                             ways=ways)

    def _optimum_fits(self, engine) -> bool:
        """Whether the optimum's programme fits, by states and bytes, whatever the plan's units: its states,
        listed before it starts, at most its cap (:meth:`_optimum_cap`), and its bytes
        (:meth:`_optimum_bytes`) granted by the engine (:meth:`~opportune.engine.schedule.OrderEngine.
        reserve_programme`).  Without a budget the listing is bounded by counted work only (it stops once
        the states pass the cap), so the choice is the
        same on a loaded machine as on an idle one; with a budget it gets a third of it (it runs inside
        the first decision on the plan), and where it cannot tell in that time the optimum does not fit
        and the fallback decides."""
        self.refusal = None
        if not self.optimal:
            self.refusal = self.SWITCHED_OFF
            return False
        from opportune.policies.states import estimate_states

        seconds = None if self.lookahead_budget is None else self.lookahead_budget / LOOKAHEAD_LISTING_PARTS
        # without a budget, a caller's deadline (evaluate --time-limit) stops the listing too: it is then out
        # of time, not a different choice (the choice stays the same on any machine)
        until = as_deadline(self.deadline if self.lookahead_budget is None else None)
        cap = self._optimum_cap(engine)
        est = estimate_states(self._sized(engine), visible=self.settings.get("visible", 2), capacity=self.settings.get("capacity"),
                              pile=self.pile, stop_above=cap, deadline=until, time_limit=seconds)
        if self.lookahead_budget is None and not est.exact and est.low <= cap and until.expired():
            raise OutOfTime("the look-ahead's listing of its optimum's states passed its deadline")
        self._optimum_states = est.states
        if not est.exact and est.low <= cap and est.states <= cap:
            # only with a budget: the listing was cut by the clock, not by the cap
            self.refusal = (f"its states could not be listed within a third of the decision budget "
                            f"({est.describe()} so far; the cap is {cap:,}; prepare it as per-plan work: "
                            "the service does so in the background)")
            return False
        self.refusal = self._refusal(engine, est, cap)
        return self.refusal is None

    def _refusal(self, engine, est, cap: int) -> str | None:
        """Why the optimum does not fit by a finished listing ``est`` (its states over ``cap``, or its bytes
        not granted by the engine), else None with its bytes granted.  O(programmes)."""
        if not est.exact or est.states > cap:
            return f"its optimum needs {est.describe()} states, more than {cap:,}"
        from opportune.policies.states import big

        need = self._optimum_bytes(engine, est)
        if not engine.reserve_programme(("lookahead optimum", self._share_key() or id(self)), need):
            return f"its optimum needs {big(need)} bytes, more than the plan's memory share grants"
        return None

    def prepare(self, engine, until=None) -> bool | None:
        """Build the optimum's programme for ``engine`` and these settings as per-plan work, without a
        decision budget: list its states, grant its bytes, solve it, going on where the last call stopped
        (in slices, e.g. in a service's idle time); once finished it is shared with every look-ahead of the
        same settings on ``engine``, and one with a budget that decides by its window because its listing did
        not fit a third of the budget takes it up at its next decision.  The states and bytes it may take are
        the decisions' own (:attr:`COMPILED_STATES`, the engine's grant).  O(states) in all.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        until : Deadline, float or None, optional
            When to stop this call (a :class:`~opportune.engine.deadline.Deadline` or a ``perf_counter``
            moment; None: never).

        Returns
        -------
        bool or None
            True once the optimum is ready; False where it does not fit, by states or bytes, or this
            look-ahead takes none (its optimum switched off, or a base rule of the caller's); None when
            ``until`` passed first (call again).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> Lookahead(visible=1, capacity=1).prepare(engine)
        True
        >>> budgeted = Lookahead(visible=1, capacity=1, budget=1e-9)     # no time to list: it takes this one
        >>> budgeted.choose_at(engine, 0, 1, (), 1.0, ("c",)), budgeted.deciding_rule
        (Action(kind='buffer', part='c', source=None), 'the action with the least expected cost of finishing (the exact optimum)')
        """
        self._suit(engine)
        key = self._share_key()
        if not self.optimal or key is None:
            return False
        if key in engine.kept.get(_READY, {}):
            return True
        jobs = engine.kept.setdefault(_PREPARING, {})
        job = jobs.get(key)
        if job is None:
            job = jobs[key] = self._preparation(engine, key)
        done = self._advance(engine, job, as_deadline(until))
        if done:        # a refusal stays: asking again answers at once
            del jobs[key]
            engine.kept.setdefault(_READY, {})[key] = job.solver
            engine.kept.setdefault(_KEPT, {})[key] = job.solver
        return done

    def _preparation(self, engine, key) -> _Preparation:
        """A new preparation: a listing of the optimum's states, or the solver already under way for these
        settings (a look-ahead with a budget whose listing fitted shares its own)."""
        from opportune.policies.states import StateListing

        cap = self._optimum_cap(engine)
        listing = StateListing(self._sized(engine), visible=self.settings.get("visible", 2),
                               capacity=self.settings.get("capacity"), pile=self.pile, stop_above=cap)
        job = _Preparation(listing, cap)
        shared = engine.kept.get(_KEPT, {}).get(key)
        if shared is not None and getattr(shared, "policy", None) is None:
            job.solver = shared
        return job

    def _advance(self, engine, job: _Preparation, until: Deadline) -> bool | None:
        """One slice of a preparation: True when solved, False when it does not fit, None out of time."""
        if job.refusal is not None:
            return False
        if job.solver is None:
            est = job.listing.advance(until)
            if est is None:
                return None
            job.refusal = self._refusal(engine, est, job.cap)
            if job.refusal is not None:
                return False
            job.solver = self._optimum_solver(engine)
            job.solver.reserve(est.states)     # compiled: no table doubling in a slice
        job.solver.deadline = until
        try:
            job.solver.value()
        except OutOfTime:
            return None
        except OptimalTooLarge as exc:
            job.refusal = str(exc)
            return False
        finally:
            job.solver.deadline = None
        return True

    def _prepared(self, engine) -> bool:
        """Whether an optimum prepared for these settings waits to be taken up (with a budget, deciding by
        the window or the base because the programme did not fit).  O(settings)."""
        if self.lookahead_budget is None or not self._too_large or not self.optimal:
            return False
        key = self._share_key()
        return key is not None and key in engine.kept.get(_READY, {})

    def decides_by_optimum(self, engine, visible: int, capacity: int | None, costs, *, pile: bool = False) -> bool:
        """Whether on ``engine`` every decision of this look-ahead is an action of least expected cost in
        the uniform bin (or with ``pile``, the pile) of ``visible`` parts, ``capacity`` locations and
        ``costs``: its world is that one, without a budget, and the programme that decides is the optimum's
        (prepared here, as its first decision would).  Its expected cost there is then the optimum's (ties
        within 1e-12 a move; tests/test_pile_compiled.py checks the pile's against its look-by-look value).
        O(1) once prepared.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        visible : int
            Units seen at a look in the uniform bin asked about.
        capacity : int or None
            Buffer locations (None: unlimited).
        costs : TimeModel or None
            The time model (None: the default one).
        pile : bool
            The world is the pile bin (its look-ahead's own programme), not the uniform bin.

        Returns
        -------
        bool
            True when the optimum's programme decides in that world.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> Lookahead(visible=1, capacity=1).decides_by_optimum(engine, 1, 1, None)
        True
        >>> Lookahead(visible=1, capacity=1).decides_by_optimum(engine, 2, 1, None)    # another world
        False
        >>> Lookahead(visible=1, capacity=1, optimal=False).decides_by_optimum(engine, 1, 1, None)
        False
        """
        from opportune.planning.costs import TimeModel

        world = (self.settings.get("visible", 2), self.settings.get("capacity"), self.settings.get("costs") or TimeModel())
        weights = self.settings.get("weights")
        if self.pile != pile or self.lookahead_budget is not None or world != (visible, capacity, costs or TimeModel()):
            return False
        if not pile and weights and len({weights.get(p.id, 1.0) for p in engine.plan.parts}) > 1:
            return False
        self._suit(engine)
        self._values(engine)
        return self._optimum

    @property
    def deciding_rule(self) -> str:
        """The rule of the programme that decides (after the first decision on a plan): on a plan written as
        ways where the optimum does not fit, the paper's rule's (see :meth:`_suit`)."""
        if self._optimum:
            return self.OPTIMAL_RULE
        return self.WAYS_RULE if self._on_ways and self.base.name == "paper" else self.rule

    @property
    def _optimum(self) -> bool:
        """Whether the programme is the optimum's (no policy evaluated)."""
        return self._evaluator is not None and getattr(self._evaluator, "policy", None) is None

    def _share_key(self):
        """What the programme's values depend on, when that is known (the default base rules: ``slack``, or
        the paper's on a plan written as ways); else None."""
        if type(self.base) not in (Slack, Opportunistic) or self.base.budget is not None:
            return None
        settings = tuple(sorted((k, repr(v)) for k, v in self.settings.items()))
        return (self.base.name, getattr(self.base, "weight", None), self.max_states, self.pile, self.optimal, settings)

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action at a state, on its machine form: the programme's (the optimum's, or the step over
        the base), else the frontier window's or the base's (see the class).

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : tuple of str
            The buffered parts.
        free : float
            Free buffer locations (``inf``: unlimited), as the base rule reads them.
        visible : tuple of str
            The look.

        Returns
        -------
        Action
            The action (``DONE`` once every unit is installed).

        Raises
        ------
        OutOfTime
            Without a budget, past the caller's :attr:`deadline` (what the programme finished stays).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> lookahead = Lookahead(visible=1, capacity=1)
        >>> lookahead.choose_at(engine, 0, 1, (), 1.0, ("c",)), lookahead.choose_at(engine, 0, 1, (), 1.0, ("a",))
        (Action(kind='buffer', part='c', source=None), Action(kind='install', part='a', source='bin'))
        """
        if mask == engine.full:
            return DONE
        self._suit(engine)
        look = LookState(engine, mask, consistent, buffer, free, visible)
        if self.lookahead_budget is None:
            return self._choose(look)
        # the whole budgeted decision with the collector paused, the programme's part and the base's:
        # a full collection that started in it took 74 ms on a 1,000-task plan against 50
        pause_collector()
        try:
            return self._choose(look)
        finally:
            resume_collector()

    def choose_looks(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                     looks) -> list[Action]:
        """:meth:`choose_at` at one state on each of ``looks``, in order: the same actions.  Without a
        budget, once the first look has found that the programme does not decide (the plan is too large
        for it), the other looks go to the fallback at once, not through the programme look by look.

        Parameters
        ----------
        engine : OrderEngine
            The plan's engine.
        mask, consistent : int
            The installed units and the open strategies.
        buffer : tuple of str
            The buffered parts.
        free : float
            Free buffer locations (``inf``: unlimited).
        looks : sequence of tuple of str
            The looks.

        Returns
        -------
        list of Action
            One per look.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]}))
        >>> Lookahead(visible=1, capacity=1, optimal=False).choose_looks(engine, 0, 1, (), 1.0, [("c",), ("a",)])
        [Action(kind='buffer', part='c', source=None), Action(kind='install', part='a', source='bin')]
        """
        if not looks:
            return []
        first = self.choose_at(engine, mask, consistent, buffer, free, looks[0])
        if self.lookahead_budget is not None or mask == engine.full or not self._too_large:
            return [first] + [self.choose_at(engine, mask, consistent, buffer, free, v) for v in looks[1:]]
        fallback = self._fallback(engine, time.perf_counter())
        batch = getattr(fallback, "choose_looks", None)
        if batch is None:       # a base of the caller's that decides look by look
            return [first] + [fallback.choose_at(engine, mask, consistent, buffer, free, v) for v in looks[1:]]
        return [first, *batch(engine, mask, consistent, buffer, free, looks[1:])]

    def _choose(self, look: LookState) -> Action:
        start = time.perf_counter()
        action = self._programme(look)
        if action is not None:
            return action
        return self._fallback(look.engine, start).choose_look(look)

    def _fallback(self, engine=None, start: float | None = None):
        """What decides where the programme does not: the frontier window (within its share of the budget
        from the decision's ``start``, a ``perf_counter`` moment, and the decision deadline on the engine),
        else the base."""
        if self._by_window and self._too_large:
            if engine is not None:
                own = (Deadline.NEVER if self.lookahead_budget is None
                       else Deadline(start + self.WINDOW_SHARE * self.lookahead_budget))
                self.window.deadline = own.sooner(engine.decision_deadline)
            return self.window
        return self.fallback_alone if self._too_large else self.fallback

    def _programme(self, look: LookState):
        """The look-ahead's action, or None where the base rule decides (a large plan, or out of time)."""
        engine, mask, consistent, buffer, _, visible = look
        self.last_cost = None
        if self._prepared(engine):      # prepared as per-plan work since: the optimum decides from now on
            self._evaluator, self._too_large, self._by_window = None, False, False
        if not self._too_large:
            start = time.perf_counter()     # the programme's share counts from here: choosing it is inside
            ev = self._values(engine)
            if ev is None:
                self._too_large = True
                return None
            own = as_deadline(self.deadline if self.lookahead_budget is None
                              else start + LOOKAHEAD_PROGRAMME_SHARE * self.lookahead_budget)
            # the decision's deadline on the engine (a service look's) binds the programme too, as it binds
            # the engine's counts: past it the base decides, budget or not
            engine_stops = engine.decision_deadline.at < own.at
            ev.deadline = own.sooner(engine.decision_deadline)
            try:
                action, self.last_cost = ev._deep(
                    lambda key: self._best(ev, engine, key, buffer, visible), ev.policy_key(mask, consistent, buffer))
                return action
            except OutOfTime:
                if self.lookahead_budget is None and not engine_stops:
                    raise                   # exact: never the base's decision in its place; the caller stops
                # this decision is the base's; the next one goes on from here
            except BudgetExceeded as exc:   # a count of the programme past the engine's deadline (a service
                if exc.reason != "time":    # look's): likewise; past a memory budget, the plan is too large
                    self._too_large = True
            except OptimalTooLarge:
                self._too_large = True      # a large plan: decide as the base does from now on
                self._by_window = self._window_serves(engine)
            finally:
                ev.deadline = None
        return None

    def _why_too_large(self) -> str:
        """Why the programmes do not fit, in words: the optimum's refusal (states or bytes) and the base's cap."""
        if self._by_window:
            return self.refusal or "its optimum needs more states than it holds"
        base = (f"the step over the base rule is evaluated on plans of at most {self.STEP_UNITS} units"
                if self._evaluator is None else f"the base rule's needs more than {self.max_states:,} states")
        if self._on_ways:
            base += "; its frontier window reads partial orders, which a plan written as ways does not have"
        return f"{self.refusal}; {base}" if self.refusal else base

    def _best(self, ev, engine, key: tuple, buffer: tuple[str, ...], visible: tuple[str, ...]):
        """``(action, its expected cost)``: the least of cost plus the base's cost to go after it; of equal
        ones the base's own action (the improvement is then never worse), else by kind and declaration order."""
        mask, consistent, _ = key
        plan = engine.plan
        look = tuple(sorted(plan.index(p) for p in visible))
        kind_rank = {"install": 0, "buffer": 1}
        ranked = [(cost + ev._after(key, look, action, nxt), kind_rank[action.kind], plan.index(action.part), action)
                  for cost, nxt, action in ev.policy_moves(key, look)]
        ranked.append((ev.costs.shake + ev._after_shake(key), 2, 0, SHAKE))
        least = min(ranked, key=lambda r: r[:3])
        tied = [r for r in ranked if r[0] <= least[0] + 1e-12]
        if ev.policy is None and len(tied) == 1:
            return least[3], least[0]   # the optimum's one best: the base's count (a look's budget early on) not asked
        try:
            base = self.base.choose_at(engine, mask, consistent, buffer,
                                       float("inf") if ev.capacity is None else ev.capacity - len(buffer), visible)
        except BudgetExceeded:
            if ev.policy is not None:
                raise
            base = None     # the optimum needs no base (a look's deadline cut its count): ties by kind and order
        for total, _, _, action in tied:
            if base is not None and same_action(action, base):
                return base, total
        return least[3], least[0]

    def decide(self, state, visible: tuple[str, ...]) -> Decision:
        """The decision with its reasons: the rule that decided (the optimum, the step over the base, the
        frontier window or the base, and why), and the expected remaining cost where a programme decided.

        Parameters
        ----------
        state : State
            The sequencer's state.
        visible : tuple of str
            The look.

        Returns
        -------
        Decision
            The decision; where the base decides, the base's own (its candidates and estimates), its rule
            saying why the look-ahead did not.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.sequencer import Sequencer
        >>> state = Sequencer(make_plan(["a", "b", "c"], {"c": ["a", "b"]}), buffer_capacity=1).state
        >>> d = Lookahead(visible=1, capacity=1).decide(state, ("c",))
        >>> d.action.kind, d.rule
        ('buffer', 'the action with the least expected cost of finishing (the exact optimum)')
        """
        sched = state.schedule
        if sched.mask == sched.engine.full:
            return Decision(DONE, "the assembly is complete")
        self._suit(sched.engine)
        start = time.perf_counter()
        action = self._programme(LookState.of(state, visible))
        if action is None and self._by_window and self._too_large:
            return self._fallback(sched.engine, start).decide(state, visible, because=self._why_too_large())
        if action is None:
            # the base rule decided (the fallback, within the budget): its own decision, with its candidates,
            # its exactness and any estimates, and why the look-ahead did not decide
            base = self._fallback().decide(state, visible)
            why = (self._why_too_large() if self._too_large and not self.optimal else
                   f"the plan is too large for the look-ahead's exact programme ({self._why_too_large()})"
                   if self._too_large else
                   "the look-ahead's programme did not finish within the decision budget (it goes on at the next look)")
            exact = base.exact and self._too_large
            return replace(base, rule=f"as the base rule ({self.base.name}), because {why}: {base.rule}",
                           exact=exact, method=base.method if base.method != "exact" or exact else self.base.name)
        return Decision(action, self.deciding_rule, note=f"expected remaining cost {self.last_cost:.4f} " + (
            "(the optimum's)" if self._optimum else f"(base: {self.base.name})"))
