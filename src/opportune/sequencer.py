"""The sequencer: the state of a cell, the looks it receives, and the actions it decides.

At every *look* (the parts the vision system sees in the bin), the sequencer
checks the look against its state, asks its policy for an action, and waits
for the outcome report.  The state changes only on reported outcomes, so a
crash between a decision and its report loses nothing.

>>> from opportune import load_plan
>>> seq = Sequencer(load_plan("example:gearbox"))
>>> seq.decide(visible=["rl", "ra"]).action
Action(kind='buffer', part='rl', source=None)
>>> seq.report("success").buffer
('rl',)
"""

from __future__ import annotations

import math
from collections import Counter as Tally
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Iterable, Literal

from opportune.engine import OrderEngine, Schedule
from opportune.engine.schedule import count_pass
from opportune.planning.plan import Plan
from opportune.policies.base import Action, Decision, Policy

Outcome = Literal["success", "failed", "defective"]
OUTCOMES = ("success", "failed", "defective")
DEFAULT_BUDGET = 0.05   # seconds per decision: a cell looks every 1–3 s
WARM_UP = 10.0          # seconds a new sequencer may spend counting its first state


class SequencerError(ValueError):
    """A look or report that contradicts the state; the state is unchanged.

    The base of :class:`LookError` and :class:`OutcomeError`; a :class:`ValueError`.

    Examples
    --------
    >>> issubclass(LookError, SequencerError), issubclass(OutcomeError, ValueError)
    (True, True)
    """


class LookError(SequencerError):
    """A look that does not fit the state, or a look when none is expected; the state is unchanged.

    Examples
    --------
    >>> from opportune import make_plan
    >>> Sequencer(make_plan(["a"])).decide(["z"])
    Traceback (most recent call last):
        ...
    opportune.sequencer.LookError: unknown part 'z' in the look: the plan's parts are a
    """
    pass


class OutcomeError(SequencerError):
    """An outcome report that does not fit the pending action; the state is unchanged.

    Examples
    --------
    >>> from opportune import make_plan
    >>> Sequencer(make_plan(["a"])).report()
    Traceback (most recent call last):
        ...
    opportune.sequencer.OutcomeError: no action is pending: decide an action (send a look) before reporting its outcome
    """
    pass


@dataclass(frozen=True)
class State:
    """Everything the sequencer knows: installed parts (the schedule), buffer contents, what is left in the bin.

    Immutable, so that simulations can branch.  A sequencer makes its states; read them from
    :attr:`Sequencer.state` or :meth:`Sequencer.report`.

    Parameters
    ----------
    schedule : Schedule
        The installed parts and every admissible way to finish.
    buffer : tuple of str, default ()
        The buffered parts, in the order they were buffered.
    capacity : int, optional
        The number of buffer locations (``None``: unlimited).
    defects : int, default 0
        Units reported defective so far.

    Examples
    --------
    >>> from opportune import make_plan
    >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}), buffer_capacity=1)
    >>> seq.step(["b"]).action.kind
    'buffer'
    >>> seq.state.buffer, seq.state.buffer_free, seq.state.in_bin
    (('b',), 0, {'a': 1})
    """

    schedule: Schedule
    buffer: tuple[str, ...] = ()
    capacity: int | None = None
    defects: int = 0

    @classmethod
    def _make(cls, schedule: Schedule, buffer: tuple[str, ...], capacity: int | None) -> "State":
        """A state from trusted values, without the dataclass's keyword handling (a simulation
        builds one per decision)."""
        s = object.__new__(cls)
        d = s.__dict__
        d["schedule"], d["buffer"], d["capacity"], d["defects"] = schedule, buffer, capacity, 0
        return s

    @property
    def plan(self) -> Plan:
        return self.schedule.plan

    @property
    def installed(self) -> tuple[str, ...]:
        return self.schedule.installed

    @property
    def is_complete(self) -> bool:
        return self.schedule.is_complete

    @property
    def buffer_free(self) -> float:
        return math.inf if self.capacity is None else self.capacity - len(self.buffer)

    @property
    def in_bin(self) -> dict[str, int]:
        """Units still expected in the bin, per part (needed, and neither installed nor buffered).

        Found once per state (the state is immutable; a look reads it to check the look and again
        to answer), from :attr:`Schedule.remaining` less the buffer: O(parts) the first time, a
        dictionary copy after that.
        """
        return dict(self._in_bin)

    @cached_property
    def _in_bin(self) -> dict[str, int]:
        count_pass("in_bin")
        left = self.schedule.remaining
        for p in self.buffer:
            left[p] = left.get(p, 0) - 1
        return {p: n for p, n in left.items() if n > 0} if self.buffer else left

    @property
    def consistent_strategies(self) -> tuple[str, ...]:
        return self.schedule.consistent_strategies

    def to_dict(self) -> dict:
        """The state as plain values (what the service and ``opportune replay --json`` show).

        Returns
        -------
        dict
            ``installed``, ``buffered``, ``in_bin``, ``capacity``, ``strategies``, ``complete`` and
            ``defects``.

        Examples
        --------
        >>> from opportune import make_plan
        >>> Sequencer(make_plan(["a", "b"], {"b": ["a"]})).state.to_dict()["in_bin"]
        {'a': 1, 'b': 1}
        """
        return {
            "installed": list(self.installed),
            "buffered": list(self.buffer),
            "in_bin": self.in_bin,
            "capacity": self.capacity,
            "strategies": list(self.consistent_strategies),
            "complete": self.is_complete,
            "defects": self.defects,
        }


@dataclass(frozen=True)
class Row:
    """One line of the trace, in the layout of the paper's Table 1 (state *before* the action).

    Parameters
    ----------
    visible, buffered, installed : tuple of str
        The look, the buffer and the installed parts before the action.
    decision : Decision
        The decision taken for the look.
    outcome : str, optional
        The outcome reported (``None`` until reported, and for ``done``).

    Examples
    --------
    >>> from opportune import make_plan
    >>> row = Sequencer(make_plan(["a", "b"], {"b": ["a"]})).run([["b"], ["a"], []])[0]
    >>> row.visible, row.action.kind, row.outcome
    (('b',), 'buffer', 'success')
    """

    visible: tuple[str, ...]
    buffered: tuple[str, ...]
    installed: tuple[str, ...]
    decision: Decision
    outcome: str | None = None

    @property
    def action(self) -> Action:
        return self.decision.action

    def to_dict(self) -> dict:
        """The row as plain values.

        Returns
        -------
        dict
            ``visible``, ``buffered``, ``installed``, ``action`` (:meth:`Action.to_dict`) and ``outcome``.

        Examples
        --------
        >>> from opportune import make_plan
        >>> Sequencer(make_plan(["a", "b"], {"b": ["a"]})).run([["b"]])[0].to_dict()
        {'visible': ['b'], 'buffered': [], 'installed': [], 'action': {'kind': 'buffer', 'part': 'b', 'source': None}, 'outcome': 'success'}
        """
        return {"visible": list(self.visible), "buffered": list(self.buffered), "installed": list(self.installed),
                "action": self.action.to_dict(), "outcome": self.outcome}


def look_ids(visible: Iterable[str]) -> tuple[str, ...]:
    """A look as a tuple of part ids, or :class:`LookError` if it is not a list of strings."""
    if isinstance(visible, str):
        raise LookError("a look is a list of part ids, not a single string")
    try:
        visible = tuple(visible)
    except TypeError:
        raise LookError("a look is a list of part ids") from None
    for part in visible:
        if not isinstance(part, str):
            raise LookError(f"part ids are strings, got {part!r}")
    return visible


def check_look(state: State, visible: Iterable[str]) -> tuple[str, ...]:
    """Validate a look against the state; return it as a tuple or raise :class:`LookError`."""
    visible = look_ids(visible)
    plan = state.plan
    for part in visible:
        if part not in plan:
            from opportune.formats.problems import unknown_part_hint

            raise LookError(f"unknown part '{part}' in the look: {unknown_part_hint(part, plan.part_ids)}")
    if state.is_complete and visible:
        raise LookError("the assembly is complete: no part should be left to see")
    in_bin = state.in_bin
    for part, n in Tally(visible).items():
        have = in_bin.get(part, 0)
        if n <= have:
            continue
        q = plan.part(part).quantity
        installed = state.installed.count(part)
        buffered = state.buffer.count(part)
        if have == 0 and installed == q:
            raise LookError(f"part '{part}' is already installed; it cannot be seen in the bin")
        if have == 0 and buffered:
            raise LookError(f"part '{part}' is in a buffer location, not in the bin")
        raise LookError(f"the look shows {n} of part '{part}' but only {have} can be in the bin "
                        f"({q} in the plan, {installed} installed, {buffered} buffered)")
    return visible


class Sequencer:
    """Keeps the state of one assembly and decides each action with a policy.

    ``decide(visible)`` checks the look and returns a :class:`Decision`; the action is then *pending*
    until ``report(outcome)``.  ``step(visible)`` does both, for a world where every action succeeds.
    The state changes only on reported outcomes.

    Parameters
    ----------
    plan : Plan or OrderEngine
        The plan to assemble; an :class:`~opportune.engine.schedule.OrderEngine` of it shares its
        memos with the other assemblies of the plan.
    policy : Policy, optional
        The decision policy (:func:`~opportune.policies.named.make_policy`); ``None``: the paper's
        rule, :class:`~opportune.policies.opportunistic.Opportunistic`, within ``budget``.
    buffer_capacity : int, optional
        Buffer locations; ``None``: unlimited.
    budget : float or None, default 0.05
        Seconds per decision for the default policy; ``None``: always exact, however long it
        takes.  A policy given explicitly keeps its own budget.
    warm_up : float or None, default 10.0
        Seconds spent here, before the first look, counting the first state exactly (on a large
        plan this chooses how it is counted and fills the memos later decisions use).  ``None``: no
        limit; 0: none.

    Raises
    ------
    ValueError
        If ``buffer_capacity`` is negative or ``budget`` is not a positive number of seconds.

    Examples
    --------
    >>> from opportune import load_plan
    >>> seq = Sequencer(load_plan("example:gearbox"))
    >>> seq.decide(visible=["rl", "ra"]).action
    Action(kind='buffer', part='rl', source=None)
    >>> seq.report("success").buffer
    ('rl',)
    >>> seq.decide(["ca"]).action
    Action(kind='install', part='ca', source='bin')
    """

    def __init__(self, plan: Plan | OrderEngine, policy: Policy | None = None, *,
                 buffer_capacity: int | None = None, budget: float | None = DEFAULT_BUDGET,
                 warm_up: float | None = WARM_UP):
        if buffer_capacity is not None and buffer_capacity < 0:
            raise ValueError("buffer capacity must be ≥ 0 (or None for unlimited)")
        if budget is not None and not budget > 0:
            raise ValueError("the decision budget must be a positive number of seconds (or None: exact)")
        if policy is None:
            from opportune.policies.opportunistic import Opportunistic

            policy = Opportunistic(budget=budget)
        self.engine = plan if isinstance(plan, OrderEngine) else OrderEngine(plan)
        self.plan = self.engine.plan
        self.policy = policy
        self.state = State(Schedule(self.engine), capacity=buffer_capacity)
        self.pending: Row | None = None
        self.trace: list[Row] = []
        self.finished = False
        self.warmed = warm_up == 0 or self.state.schedule.warm_up(warm_up)
        self.engine.maintain()

    # ------------------------------------------------------------ deciding

    def decide(self, visible: Iterable[str] = ()) -> Decision:
        """Decide the next action for a look.

        The action is pending until :meth:`report` (or :meth:`cancel`).  Once the assembly is complete,
        an empty look is answered once with ``done``; any look after that is refused.

        Parameters
        ----------
        visible : iterable of str, default ()
            The part ids the vision system sees in the bin (a part id once per unit seen).

        Returns
        -------
        Decision
            The action, why it was chosen, and whether it was decided exactly.

        Raises
        ------
        LookError
            If the look does not fit the state (an unknown part, more units than can be in the bin, a
            part already installed or buffered), an action is pending, or the run is done; the state is
            unchanged.
        RuntimeError
            If the policy chose an action the state does not allow (a policy bug); the state is
            unchanged.

        Examples
        --------
        >>> from opportune import make_plan
        >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}))
        >>> seq.decide(["b"]).action
        Action(kind='buffer', part='b', source=None)
        >>> seq.decide(["a"])
        Traceback (most recent call last):
            ...
        opportune.sequencer.LookError: 'buffer b' is pending: report its outcome (or cancel it) before the next look
        """
        look = self._check_ready(visible)
        # The engine (shared by every assembly of the plan) trims and evicts its memos only between
        # decisions: after each outcome (see OrderEngine.deciding and OrderEngine.maintain).
        with self.engine.deciding():
            decision = self._ask(look)
        self._check_decision(decision, look)
        return self._pend(look, decision)

    #: How a finished run is described when a look comes after ``done``.
    COMPLETE = "the assembly is complete"

    def _ask(self, look: tuple[str, ...]) -> Decision:
        """The policy's decision for a checked look (a cell of several fixtures translates it)."""
        return self.policy.decide(self.state, look)

    def _check_look(self, visible: Iterable[str]) -> tuple[str, ...]:
        return check_look(self.state, visible)

    def _held(self, part: str) -> str:
        """What a buffer location holds for a part taken by an action (the part itself here)."""
        return part

    def replay(self, visible: Iterable[str], action: Action | Decision) -> Decision:
        """Take a recorded action for a look without asking the policy.

        An estimated decision depends on time and chance, so a log is replayed by what was done, not
        decided again.  The action is pending until :meth:`report`, as after :meth:`decide`.

        Parameters
        ----------
        visible : iterable of str
            The look the action was decided for.
        action : Action or Decision
            The recorded action (or the whole recorded decision).

        Returns
        -------
        Decision
            The recorded decision (``method="replayed"`` when only an action was given).

        Raises
        ------
        LookError
            If the look or the action does not fit the state (which is then unchanged).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.policies.base import Action
        >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}))
        >>> seq.replay(["a", "b"], Action("install", "a", "bin")).method
        'replayed'
        >>> seq.report().installed
        ('a',)
        """
        look = self._check_ready(visible)
        decision = action if isinstance(action, Decision) else Decision(action, "replayed from the log", exact=False,
                                                                       method="replayed")
        try:
            self._check_decision(decision, look)
        except RuntimeError as exc:
            raise LookError(f"the recorded action does not fit the state: {exc}") from None
        return self._pend(look, decision)

    def _check_ready(self, visible: Iterable[str]) -> tuple[str, ...]:
        if self.pending is not None:
            raise LookError(f"'{self.pending.action}' is pending: report its outcome (or cancel it) before the next look")
        if self.finished:
            raise LookError(f"{self.COMPLETE} and was reported done: start a new run")
        return self._check_look(visible)

    def _pend(self, look: tuple[str, ...], decision: Decision) -> Decision:
        row = Row(look, self.state.buffer, self.state.installed, decision)
        if decision.action.kind == "done":
            self.trace.append(row)
            self.finished = True
        else:
            self.pending = row
        return decision

    def _check_decision(self, decision: Decision, look: tuple[str, ...]) -> None:
        """A policy bug must not corrupt the state: refuse actions the state does not allow."""
        a = decision.action
        if a.kind == "install":
            if a.source == "bin" and a.part not in look:
                raise RuntimeError(f"policy {self.policy.name} installs '{a.part}' from the bin but it is not visible")
            if a.source == "buffer" and a.part not in self.state.buffer:
                raise RuntimeError(f"policy {self.policy.name} installs '{a.part}' from the buffer but it is not there")
            if not self.state.schedule.can_install(a.part):
                raise RuntimeError(f"policy {self.policy.name} installs '{a.part}', which cannot go in now")
        elif a.kind == "buffer":
            if a.part not in look or self.state.buffer_free <= 0:
                raise RuntimeError(f"policy {self.policy.name} buffers '{a.part}' without a visible part or a free location")

    def cancel(self) -> None:
        """Drop the pending action (the robot did not carry it out); the state is unchanged.

        Raises
        ------
        OutcomeError
            If no action is pending.

        Examples
        --------
        >>> from opportune import make_plan
        >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}))
        >>> seq.decide(["a"]).action.kind
        'install'
        >>> seq.cancel()
        >>> seq.pending is None
        True
        """
        if self.pending is None:
            raise OutcomeError("no action is pending")
        self.pending = None
        self.engine.maintain()

    # ------------------------------------------------------------ outcomes

    def report(self, outcome: Outcome = "success", *, keep: Literal["bin", "buffer"] = "bin") -> State:
        """Apply the outcome of the pending action and return the new state.

        Parameters
        ----------
        outcome : {"success", "failed", "defective"}, default "success"
            ``success``: the action happened.  ``failed``: an install or buffer move did not happen.
            ``defective``: the part is discarded; the plan waits for a replacement unit in the bin.
        keep : {"bin", "buffer"}, default "bin"
            For a failed install: the part goes back to the bin, or stays in the gripper and is put in
            a buffer location.

        Returns
        -------
        State
            The new state (also :attr:`state`).

        Raises
        ------
        OutcomeError
            If no action is pending, the outcome or ``keep`` is unknown, a shake is reported other than
            successful, or ``keep="buffer"`` finds the buffer full; the state is unchanged.

        Examples
        --------
        >>> from opportune import make_plan
        >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}))
        >>> seq.decide(["a"]).action.part
        'a'
        >>> seq.report("failed", keep="buffer").buffer
        ('a',)
        >>> seq.report()
        Traceback (most recent call last):
            ...
        opportune.sequencer.OutcomeError: no action is pending: decide an action (send a look) before reporting its outcome
        """
        if self.pending is None:
            raise OutcomeError("no action is pending: decide an action (send a look) before reporting its outcome")
        if outcome not in OUTCOMES:
            raise OutcomeError(f"unknown outcome '{outcome}': use one of {', '.join(OUTCOMES)}")
        if keep not in ("bin", "buffer"):
            raise OutcomeError(f"keep must be 'bin' or 'buffer', not '{keep}'")
        action = self.pending.action
        state = self.state
        if action.kind == "shake":
            if outcome != "success":
                raise OutcomeError("a shake can only succeed")
        elif action.kind == "buffer":
            if outcome == "success":
                state = replace(state, buffer=state.buffer + (action.part,))
            elif outcome == "defective":
                state = replace(state, defects=state.defects + 1)
        elif action.kind == "install":
            from_buffer = action.source == "buffer"
            held = self._held(action.part)
            buffer = _without(state.buffer, held) if from_buffer else state.buffer
            if outcome == "success":
                state = replace(state, schedule=state.schedule.install(action.part), buffer=buffer)
            elif outcome == "defective":
                state = replace(state, buffer=buffer, defects=state.defects + 1)
            elif keep == "buffer":
                if not from_buffer:
                    if state.buffer_free <= 0:
                        raise OutcomeError("the buffer is full: report keep='bin' for this failed install")
                    state = replace(state, buffer=state.buffer + (held,))
            else:
                state = replace(state, buffer=buffer)
        self.state = state
        self.trace.append(replace(self.pending, outcome=outcome if keep == "bin" or outcome != "failed"
                                  else "failed, buffered"))
        self.pending = None
        # between looks: the memo upkeep held back during the decision (the robot is moving now)
        self.engine.maintain()
        return state

    def step(self, visible: Iterable[str] = ()) -> Decision:
        """Decide for a look and report success at once (a world where every action works).

        Parameters
        ----------
        visible : iterable of str, default ()
            The look, as in :meth:`decide`.

        Returns
        -------
        Decision
            The decision taken.

        Examples
        --------
        >>> from opportune import make_plan
        >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}), buffer_capacity=0)
        >>> seq.step(["b"]).action.kind
        'shake'
        >>> seq.step(["a"]).action, seq.state.installed
        (Action(kind='install', part='a', source='bin'), ('a',))
        """
        decision = self.decide(visible)
        if decision.action.kind != "done":
            self.report("success")
        return decision

    def run(self, looks: Iterable[Iterable[str]]) -> list[Row]:
        """Step through looks, every action succeeding; close with ``done`` if the assembly completes.

        Parameters
        ----------
        looks : iterable of iterable of str
            One look per action.

        Returns
        -------
        list of Row
            The whole trace (:attr:`trace`), in the layout of the paper's Table 1.

        Examples
        --------
        >>> from opportune import make_plan
        >>> rows = Sequencer(make_plan(["a", "b"], {"b": ["a"]})).run([["b"], ["a"], []])
        >>> [str(row.action) for row in rows]
        ['buffer b', 'install a', 'install b (from buffer)', 'done']
        """
        for look in looks:
            self.step(look)
        if self.state.is_complete and not self.finished:
            self.step(())
        return self.trace


def _without(items: tuple[str, ...], part: str) -> tuple[str, ...]:
    i = items.index(part)
    return items[:i] + items[i + 1:]
