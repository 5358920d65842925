"""The machine form of a state at a look, as one frozen value: what a policy decides on.

A policy that decides on masks (:class:`~opportune.policies.base.DecidesOnMasks`) is asked about the
engine, the installed units' mask, the consistent strategies, the buffer, its free locations and the
look.  Those six travel together through the answering layer and the rules as one :class:`LookState`,
which also answers what each of them derives (the units remaining, the candidates, a part's next unit).

>>> from opportune import make_plan
>>> from opportune.engine import OrderEngine
>>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
>>> look = LookState(engine, 0, engine.all_strategies, ("c",), 1.0, ("a", "b", "a"))
>>> look.installable(), look.visible_parts(), look.steps_left
(['a', 'b'], ['a', 'b'], 3)
"""

from __future__ import annotations

from collections import namedtuple

from opportune.engine import Schedule

__all__ = ["LookState"]


class LookState(namedtuple("LookState", "engine mask consistent buffer free visible")):
    """One state at one look, in the engine's terms (frozen: a changed state is a new value).

    A named tuple of the six, in ``choose_at``'s order (``policy.choose_at(*look)``): made at every
    decision, so as cheap to make as a tuple.

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    mask : int
        The installed units, as the engine's bit mask.
    consistent : int
        The strategies still consistent, as a bit mask.
    buffer : tuple of str
        The buffered parts, in the order they were buffered.
    free : float
        Free buffer locations (``math.inf``: unlimited).
    visible : tuple of str
        The look (a part once per visible unit).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
    >>> LookState(engine, 0b001, 1, (), 1.0, ("c",)).installable_in_bin()
    ['c']
    """

    __slots__ = ()

    @classmethod
    def of(cls, state, visible: tuple[str, ...]) -> LookState:
        """The look state of a sequencer's state and a look.

        Parameters
        ----------
        state : State
            The sequencer's state (its schedule, buffer and free locations).
        visible : tuple of str
            The look.

        Returns
        -------
        LookState
            The machine form.

        Examples
        --------
        >>> from opportune import make_plan, Sequencer
        >>> LookState.of(Sequencer(make_plan(["a", "b"], {})).state, ("b",)).visible
        ('b',)
        """
        sched = state.schedule
        return cls(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)

    @property
    def remaining(self) -> int:
        """The units still to install, as a bit mask."""
        return self.engine.full & ~self.mask

    @property
    def steps_left(self) -> int:
        """How many units are still to install."""
        return (self.engine.full & ~self.mask).bit_count()

    @property
    def complete(self) -> bool:
        """Whether every unit is installed."""
        return self.mask == self.engine.full

    @property
    def schedule(self) -> Schedule:
        """The state as a :class:`~opportune.engine.Schedule`: every exact count goes through it."""
        return Schedule.at(self.engine, self.mask, self.consistent)

    def installable(self) -> list[str]:
        """The installable parts among the visible and the buffered ones.

        Returns
        -------
        list of str
            The candidates, in declaration order.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> LookState(engine, 0, 1, ("b",), 1.0, ("c",)).installable()
        ['b']
        """
        return self.engine.installable_among(self.mask, self.consistent, (*self.visible, *self.buffer))

    def installable_in_bin(self) -> list[str]:
        """The installable parts among the visible ones.

        Returns
        -------
        list of str
            The bin's candidates.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b", "c"], {"c": ["a"]}))
        >>> LookState(engine, 0, 1, ("b",), 1.0, ("c",)).installable_in_bin()
        []
        """
        return self.engine.installable_among(self.mask, self.consistent, self.visible)

    def visible_parts(self) -> list[str]:
        """The visible parts, each once, in the look's order.

        Returns
        -------
        list of str
            The parts.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b"], {}))
        >>> LookState(engine, 0, 1, (), 1.0, ("b", "a", "b")).visible_parts()
        ['b', 'a']
        """
        return list(dict.fromkeys(self.visible))

    def unit(self, part: str) -> int:
        """The engine's unit a part's next install would be.

        Parameters
        ----------
        part : str
            The part.

        Returns
        -------
        int
            The unit's index.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b"], {}))
        >>> LookState(engine, 0, 1, (), 1.0, ("b",)).unit("b")
        1
        """
        return self.engine.next_unit(self.mask, self.engine.plan.index(part))

    def without_buffer(self) -> LookState:
        """The same state with the buffered parts out of sight (the bin's candidates only).

        Returns
        -------
        LookState
            A new value with an empty buffer.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> engine = OrderEngine(make_plan(["a", "b"], {}))
        >>> LookState(engine, 0, 1, ("a",), 1.0, ("b",)).without_buffer().installable()
        ['b']
        """
        return self._replace(buffer=())
