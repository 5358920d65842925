"""The sequencer of a cell with several fixtures fed from one bin (several products at once).

The cell's plan is a joint plan (:mod:`opportune.planning.products`): its parts are units
``x@i`` (part ``x`` on fixture ``i``).  The bin and the buffer hold part *kinds*: a look
shows kinds (``x``), and a seen or buffered ``x`` can become any unit ``x@i`` still needed.

Deciding is a translation, so that every policy works unchanged: the look of kinds is
expanded into a look of the units still needed (each visible ``x`` stands for every
``x@i`` not yet installed), the buffer likewise, and the policy decides on the joint plan.
An install's part is the unit, which names the fixture (``install x@2``: part ``x`` on
fixture 2); a buffer move's part is the kind (a buffered ``x`` can later go to any fixture
needing it).  With these views the paper's rule installs where the most options are kept
across all products in progress, and buffers the part needed earliest by any of them.

With one fixture (or fixtures sharing no kind) kinds and units correspond one to one, and
the decisions are those of :class:`~opportune.sequencer.Sequencer` on the single plan.

>>> from opportune import make_plan
>>> from opportune.planning.products import several_products
>>> seq = MultiSequencer(several_products(make_plan(["a", "b"], {"b": ["a"]}), 2), budget=None)
>>> seq.decide(["b", "a"]).action
Action(kind='install', part='a@1', source='bin')
"""

from __future__ import annotations

from collections import Counter as Tally
from collections.abc import Iterable
from dataclasses import dataclass, replace

from opportune.engine import OrderEngine, Schedule
from opportune.planning.plan import Plan
from opportune.policies.base import Action, Decision, Policy, shared_action
from opportune.planning.products import split_unit
from opportune.sequencer import DEFAULT_BUDGET, WARM_UP, LookError, Sequencer, State, look_ids

__all__ = ["CellState", "Layout", "MultiSequencer", "check_kinds", "fit_policy", "layout_of", "split_action"]


class Layout:
    """Which unit of the joint plan is which part kind on which fixture.

    ``units[kind]``: ``(part index, unit id)`` of each fixture's copy, in fixture order.
    Raises :class:`~opportune.planning.products.ProductsError` if a part id is not ``KIND@FIXTURE``.
    O(parts).
    """

    def __init__(self, plan: Plan):
        self.plan = plan
        self.kind: dict[str, str] = {}
        self.fixture: dict[str, int] = {}
        self.units: dict[str, list[tuple[int, str]]] = {}
        for i, pid in enumerate(plan.part_ids):
            kind, fixture = split_unit(pid)
            self.kind[pid] = kind
            self.fixture[pid] = fixture
            self.units.setdefault(kind, []).append((i, pid))
        self.n_fixtures = max(self.fixture.values())
        #: True if no kind is needed on two fixtures: kinds and units then correspond one to one.
        self.one_to_one = all(len(us) == 1 for us in self.units.values())

    def needed(self, engine: OrderEngine, mask: int, kind: str) -> list[str]:
        """The units of ``kind`` with a unit still to install (fixture order).  O(fixtures)."""
        return [pid for i, pid in self.units[kind] if engine.next_unit(mask, i) is not None]

    def view(self, engine: OrderEngine, mask: int, kinds: Iterable[str]) -> tuple[str, ...]:
        """Kinds (a look, or the buffer, in order) as the units they can become: a kind held ``m`` times
        becomes each part of it still needed, ``m`` times but no more than that part has units left.
        (Without the repeats, two buffered units of one part on one fixture would read as one, and a
        programme that sizes the buffer by its contents would see a free location that is not there.)
        O(kinds × fixtures × quantity)."""
        out: list[str] = []
        for kind, m in Tally(kinds).items():
            for i, pid in self.units[kind]:
                u = engine.next_unit(mask, i)
                if u is not None:
                    out.extend([pid] * min(m, engine.first[i] + self.plan.parts[i].quantity - u))
        return tuple(out)

    def in_bin(self, schedule: Schedule, buffer: tuple[str, ...]) -> dict[str, int]:
        """Units still expected in the bin, per kind: still to install on some fixture, not buffered."""
        left: Tally = Tally()
        for pid, n in schedule.remaining.items():
            left[self.kind[pid]] += n
        left.subtract(Tally(buffer))
        return {k: n for k, n in left.items() if n > 0}


_LAYOUTS: dict[int, tuple[Plan, Layout]] = {}


def layout_of(plan: Plan) -> Layout:
    """The (cached) :class:`Layout` of a joint plan."""
    hit = _LAYOUTS.get(id(plan))
    if hit is None or hit[0] is not plan:
        if len(_LAYOUTS) > 64:
            _LAYOUTS.clear()
        hit = _LAYOUTS[id(plan)] = (plan, Layout(plan))
    return hit[1]


@dataclass(frozen=True)
class CellState(State):
    """The state of a multi-fixture cell: the joint schedule, and the buffer holding part kinds.

    Made by :class:`MultiSequencer`; ``in_bin`` counts part kinds.

    Parameters
    ----------
    schedule : Schedule
        The joint plan's schedule.
    buffer : tuple of str, default ()
        The buffered part kinds, in the order they were buffered.
    capacity : int, optional
        Buffer locations (``None``: unlimited).
    defects : int, default 0
        Units reported defective so far.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.planning.products import several_products
    >>> seq = MultiSequencer(several_products(make_plan(["a", "b"], {"b": ["a"]}), 2), budget=None)
    >>> seq.state.in_bin
    {'a': 2, 'b': 2}
    """

    @property
    def layout(self) -> Layout:
        return layout_of(self.plan)

    @property
    def in_bin(self) -> dict[str, int]:
        """Units still expected in the bin, per part kind."""
        return self.layout.in_bin(self.schedule, self.buffer)

    def fixtures(self) -> list[dict]:
        """Each fixture's installed parts (kinds, in order) and whether its product is complete.

        Returns
        -------
        list of dict
            ``{"fixture": i, "installed": [...], "complete": bool}``, fixture 1 first.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.planning.products import several_products
        >>> seq = MultiSequencer(several_products(make_plan(["a", "b"], {"b": ["a"]}), 2), budget=None)
        >>> seq.step(["b", "a"]).action.part
        'a@1'
        >>> seq.state.fixtures()
        [{'fixture': 1, 'installed': ['a'], 'complete': False}, {'fixture': 2, 'installed': [], 'complete': False}]
        """
        lay = self.layout
        remaining = self.schedule.remaining
        out = [{"fixture": i, "installed": [], "complete": True} for i in range(1, lay.n_fixtures + 1)]
        for pid in self.installed:
            out[lay.fixture[pid] - 1]["installed"].append(lay.kind[pid])
        for pid in remaining:
            out[lay.fixture[pid] - 1]["complete"] = False
        return out

    def to_dict(self) -> dict:
        out = super().to_dict()
        out["fixtures"] = self.fixtures()
        return out

    def view(self, visible: tuple[str, ...]) -> tuple[State, tuple[str, ...]]:
        """The state and look as a policy sees them on the joint plan: units, not kinds.

        Each kind in the look or the buffer becomes every unit it can be; the buffer's capacity grows by
        as many, so that its free locations stay those of the real buffer.

        Parameters
        ----------
        visible : tuple of str
            A look of part kinds.

        Returns
        -------
        tuple of (State, tuple of str)
            The state on the joint plan, and the look as units.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.planning.products import several_products
        >>> seq = MultiSequencer(several_products(make_plan(["a", "b"], {"b": ["a"]}), 2), budget=None)
        >>> seq.step(["a"]).action.part
        'a@1'
        >>> seq.state.view(("a", "b"))[1]
        ('a@2', 'b@1', 'b@2')
        """
        sched, lay = self.schedule, self.layout
        look = lay.view(sched.engine, sched.mask, visible)
        buffer = lay.view(sched.engine, sched.mask, self.buffer)
        capacity = None if self.capacity is None else self.capacity + len(buffer) - len(self.buffer)
        return State._make(sched, buffer, capacity), look


def fit_policy(policy, layout: Layout):
    """The policy a cell uses: ``policy`` itself, except the policies that model the bin.

    The look-ahead's exact programme and the rollout's sampled futures model a bin of the joint
    plan's units, not of kinds: when a kind is needed on several fixtures they decide by their base
    rule (``slack``) instead, within their budget.

    Parameters
    ----------
    policy : Policy
        The policy asked for.
    layout : Layout
        The cell's layout (:func:`layout_of`).

    Returns
    -------
    Policy
        The policy that decides.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.planning.products import several_products
    >>> from opportune.policies.named import make_policy
    >>> layout = layout_of(several_products(make_plan(["a", "b"], {"b": ["a"]}), 2))
    >>> fit_policy(make_policy("lookahead"), layout).name, fit_policy(make_policy("paper"), layout).name
    ('slack', 'paper')
    """
    from opportune.policies.rollout import Rollout
    from opportune.policies.variants import Slack
    from opportune.policies.lookahead import Lookahead

    if layout.one_to_one:
        return policy
    if isinstance(policy, Lookahead):
        return policy.fallback_alone
    if isinstance(policy, Rollout):
        return Slack(budget=policy.budget)
    return policy


def check_kinds(state: CellState, visible: Iterable[str]) -> tuple[str, ...]:
    """Validate a look of part kinds against a cell's state; return it or raise :class:`LookError`."""
    visible = look_ids(visible)
    lay = state.layout
    for part in visible:
        if part not in lay.units:
            from opportune.formats.problems import unknown_part_hint

            if part in lay.kind:
                raise LookError(f"unknown part '{part}' in the look (the bin holds part kinds: say "
                                f"'{split_unit(part)[0]}', not the fixture's unit)")
            hint = unknown_part_hint(part, lay.units, "the products' part kinds")
            raise LookError(f"unknown part '{part}' in the look: {hint}")
    if state.is_complete and visible:
        raise LookError("every product is complete: no part should be left to see")
    in_bin = state.in_bin
    for part, n in Tally(visible).items():
        have = in_bin.get(part, 0)
        if n > have:
            buffered = state.buffer.count(part)
            raise LookError(f"the look shows {n} of part '{part}' but only {have} can be in the bin "
                            f"({buffered} buffered, the rest installed on their fixtures)")
    return visible


class MultiSequencer(Sequencer):
    """Keeps the state of a cell of several fixtures fed from one bin, and decides with a policy.

    A :class:`~opportune.sequencer.Sequencer` (``decide``, ``report``, ``cancel``, ``step``, ``run``,
    ``state``, ``trace``, with the same errors) on a joint plan; looks and buffered parts are part
    kinds, installs name the unit (``x@2``: ``x`` on fixture 2).

    Parameters
    ----------
    plan : Plan or OrderEngine
        A joint plan (:func:`~opportune.planning.products.several_products`,
        :func:`~opportune.planning.products.combine_products`), or its engine.
    policy : Policy, optional
        The policy asked for (``None``: the paper's rule within ``budget``); a policy that models the
        bin may decide by its base rule instead (:func:`fit_policy`).
    buffer_capacity : int, optional
        Buffer locations (``None``: unlimited).
    budget : float or None, default 0.05
        Seconds per decision of the default policy (``None``: exact).
    warm_up : float or None, default 10.0
        Seconds spent counting the first state before the first look (as for ``Sequencer``).

    Raises
    ------
    ValueError
        If ``buffer_capacity`` is negative or ``budget`` is not a positive number of seconds.

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.planning.products import several_products
    >>> seq = MultiSequencer(several_products(make_plan(["a", "b"], {"b": ["a"]}), 2), budget=None)
    >>> seq.decide(["b", "a"]).action
    Action(kind='install', part='a@1', source='bin')
    >>> seq.report().installed, seq.n_fixtures
    (('a@1',), 2)
    """

    COMPLETE = "every product is complete"

    def __init__(self, plan: Plan | OrderEngine, policy: Policy | None = None, *,
                 buffer_capacity: int | None = None, budget: float | None = DEFAULT_BUDGET,
                 warm_up: float | None = WARM_UP):
        engine = plan if isinstance(plan, OrderEngine) else OrderEngine(plan)
        self.layout = layout_of(engine.plan)     # before the policy is set: fitting it needs the layout
        super().__init__(engine, policy, buffer_capacity=buffer_capacity, budget=budget, warm_up=warm_up)
        self.state = CellState(self.state.schedule, capacity=buffer_capacity)

    @property
    def policy(self):
        """The policy deciding (see :func:`fit_policy`); setting it sets the policy asked for."""
        return self._policy

    @policy.setter
    def policy(self, policy) -> None:
        self.asked_policy = policy
        self._policy = fit_policy(policy, self.layout)

    @property
    def n_fixtures(self) -> int:
        return self.layout.n_fixtures

    # ------------------------------------------------------------ deciding

    def _ask(self, look: tuple[str, ...]) -> Decision:
        """The policy decides on the joint plan (each seen kind as every unit still needed)."""
        view, units = self.state.view(look)
        return self._translate(self.policy.decide(view, units))

    def _check_look(self, visible) -> tuple[str, ...]:
        return check_kinds(self.state, visible)

    def _held(self, part: str) -> str:
        return self.layout.kind[part]       # a buffer location holds a kind, for whichever fixture needs it

    def _translate(self, decision: Decision) -> Decision:
        """A policy's decision on the joint plan as the cell's: a buffered unit becomes its kind."""
        a = decision.action
        if a.kind == "buffer":
            decision = replace(decision, action=shared_action("buffer", self.layout.kind[a.part]))
        if self.policy is not self.asked_policy:
            decision = replace(decision, rule=f"as the base rule ({self.policy.name}), because the "
                                              f"{self.asked_policy.name}'s model is a bin of one product's parts: "
                                              f"{decision.rule}")
        if decision.action.kind == "done":
            decision = replace(decision, rule="every product is complete")
        return decision

    def _check_decision(self, decision: Decision, look: tuple[str, ...]) -> None:
        """Refuse actions the state does not allow (a policy bug, or a bad recorded action)."""
        a = decision.action
        lay = self.layout
        if a.kind == "install":
            if a.part not in lay.kind:
                raise RuntimeError(f"'{a.part}' is not a part of this cell: an install names the fixture (KIND@FIXTURE)")
            kind = lay.kind[a.part]
            if a.source == "bin" and kind not in look:
                raise RuntimeError(f"policy {self.policy.name} installs '{kind}' from the bin but it is not visible")
            if a.source == "buffer" and kind not in self.state.buffer:
                raise RuntimeError(f"policy {self.policy.name} installs '{kind}' from the buffer but it is not there")
            if a.source not in ("bin", "buffer"):
                raise RuntimeError(f"an install comes from the bin or the buffer, not {a.source!r}")
            if not self.state.schedule.can_install(a.part):
                raise RuntimeError(f"policy {self.policy.name} installs '{kind}' on fixture {lay.fixture[a.part]}, "
                                   "which cannot take it now")
        elif a.kind == "buffer":
            if a.part not in look or self.state.buffer_free <= 0:
                raise RuntimeError(f"policy {self.policy.name} buffers '{a.part}' without a visible part or a free location")
        elif a.kind == "done" and not self.state.is_complete:
            raise RuntimeError("'done' before every product is complete")


def split_action(action: Action) -> tuple[str | None, int | None]:
    """``(part kind, fixture)`` of a cell's action.

    Parameters
    ----------
    action : Action
        A cell's action.

    Returns
    -------
    tuple of (str or None, int or None)
        The fixture of an install; ``None`` for a buffer move (a buffered kind goes to a fixture
        later); ``(None, None)`` for a shake or done.

    Raises
    ------
    ProductsError
        For an install whose part names no fixture.

    Examples
    --------
    >>> split_action(Action("install", "x@2", "bin")), split_action(Action("buffer", "x"))
    (('x', 2), ('x', None))
    """
    if action.kind == "install":
        return split_unit(action.part)
    if action.kind == "buffer":
        return action.part, None
    return None, None

