"""What a policy sees and says: looks, actions, decisions and their reasons.

A *policy* is asked, at every look, for the next action given the state of the
cell.  The opportunistic policy of the paper, the alternatives it is compared
with (pallets, shaking, kitting, buffering, statistics) and the optimum all
implement the same :class:`Policy` interface, so the sequencer, the
simulation and the service share one decision path.
"""

from __future__ import annotations

import gc
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Literal, Protocol, runtime_checkable

# An estimated decision stops early once it is SURE of its choice, or as sure that no other candidate is
# better by more than INDIFFERENT (a near tie): engine/tuning.py says why; answers.py uses them and
# Decision.certainty states them.
from opportune.engine.tuning import INDIFFERENT, SURE

# A policy reads the sequencer's State (``schedule``, ``buffer``, ``buffer_free``, ``plan``) but does not
# import it: the sequencer uses the policies, not the other way round.
State = Any

ActionKind = Literal["install", "buffer", "shake", "done"]

# how earlier versions wrote a near tie into a decision's note (read back by Decision.recorded)
_OLD_NEAR_TIE = "stopped early: with probability >= "
Source = Literal["bin", "buffer"]


@dataclass(frozen=True)
class Action:
    """One robot action.

    Parameters
    ----------
    kind : {"install", "buffer", "shake", "done"}
        ``install`` a part (from the bin or a buffer location), ``buffer`` a visible part (bin → a
        free buffer location), ``shake`` the bin (and look again), or ``done``.
    part : str, optional
        The part installed or buffered (``None`` for ``shake`` and ``done``).
    source : {"bin", "buffer"}, optional
        Where an installed part comes from.

    Examples
    --------
    >>> str(Action("install", "a", "buffer")), str(Action("shake"))
    ('install a (from buffer)', 'shake')
    """

    kind: ActionKind
    part: str | None = None
    source: Source | None = None

    def __str__(self) -> str:
        if self.kind == "install":
            return f"install {self.part}" + (" (from buffer)" if self.source == "buffer" else "")
        if self.kind == "buffer":
            return f"buffer {self.part}"
        return self.kind

    def to_dict(self) -> dict:
        """The action as JSON values.

        Returns
        -------
        dict
            ``kind``, ``part`` and ``source``.

        Examples
        --------
        >>> Action("buffer", "a").to_dict()
        {'kind': 'buffer', 'part': 'a', 'source': None}
        """
        return {"kind": self.kind, "part": self.part, "source": self.source}

    @classmethod
    def from_dict(cls, d: dict) -> "Action":
        """The action :meth:`to_dict` wrote.

        Parameters
        ----------
        d : dict
            ``kind``, and ``part`` and ``source`` where the action has them.

        Returns
        -------
        Action
            The action.

        Raises
        ------
        KeyError
            If ``d`` has no ``kind``.

        Examples
        --------
        >>> Action.from_dict({"kind": "install", "part": "a", "source": "bin"})
        Action(kind='install', part='a', source='bin')
        """
        return cls(d["kind"], d.get("part"), d.get("source"))


INSTALL_FROM_BIN = "bin"
SHAKE = Action("shake")
DONE = Action("done")
_SHARED_ACTIONS: dict[tuple, Action] = {}


def shared_action(kind: ActionKind, part: str | None = None, source: Source | None = None) -> Action:
    """``Action(kind, part, source)``, one shared object per value (actions are immutable, and
    a simulation asks for millions of the same few)."""
    key = (kind, part, source)
    a = _SHARED_ACTIONS.get(key)
    if a is None:
        a = _SHARED_ACTIONS[key] = Action(kind, part, source)
    return a


@dataclass(frozen=True)
class Candidate:
    """A part that could be installed now, with what installing it keeps open.

    Parameters
    ----------
    part : str
        The part.
    source : {"bin", "buffer"}
        Where it would come from.
    options : int
        Admissible completions left after installing it.
    total : int or None
        Admissible completions now (``None``: not counted within the decision budget).
    cost : float
        Its handling cost, acquire + install.
    buffered_at : int, optional
        Its position in the buffer (0: buffered longest).

    Examples
    --------
    >>> Candidate("a", "bin", 1, 2, 2.0).to_dict()
    {'part': 'a', 'source': 'bin', 'options': '1', 'total': '2', 'cost': 2.0, 'buffered_at': None}
    """

    part: str
    source: Source
    options: int          # admissible completions left after installing it
    total: int | None     # admissible completions now (None: not counted within the decision budget)
    cost: float           # acquire + install
    buffered_at: int | None = None  # position in the buffer (0 = buffered longest)

    def to_dict(self) -> dict:
        """The candidate as JSON values; counts as decimal strings (they may exceed any JSON number).

        Returns
        -------
        dict
            ``part``, ``source``, ``options``, ``total``, ``cost`` and ``buffered_at``.

        Examples
        --------
        >>> Candidate("a", "buffer", 10 ** 30, None, 1.0, buffered_at=0).to_dict()["options"]
        '1000000000000000000000000000000'
        """
        return {"part": self.part, "source": self.source, "options": str(self.options),
                "total": None if self.total is None else str(self.total), "cost": self.cost, "buffered_at": self.buffered_at}


@dataclass(frozen=True)
class Estimate:
    """An estimated quantity of one part that decided an action, with its standard error.

    Parameters
    ----------
    part : str
        The part.
    kind : {"share", "position", "slack"}
        ``"share"``: the share of admissible completions that keep the part next (its options over
        all completions); ``"position"``: its expected position, 1 = next; ``"slack"``: the slack
        rule's value, expected position less what the order alone gives.
    value, se : float
        The estimate and its standard error.
    source : {"bin", "buffer"}, optional
        Where the part is.

    Examples
    --------
    >>> Estimate("a", "share", 0.25, 0.01, "bin").to_dict()
    {'part': 'a', 'kind': 'share', 'value': 0.25, 'se': 0.01, 'source': 'bin'}
    """

    part: str
    kind: Literal["share", "position", "slack"]
    value: float
    se: float
    source: Source | None = None

    def to_dict(self) -> dict:
        """The estimate as JSON values.

        Returns
        -------
        dict
            ``part``, ``kind``, ``value``, ``se`` and ``source``.

        Examples
        --------
        >>> Estimate("a", "position", 1.5, 0.1).to_dict()["kind"]
        'position'
        """
        return {"part": self.part, "kind": self.kind, "value": self.value, "se": self.se, "source": self.source}


@dataclass(frozen=True)
class Decision:
    """An action with the reasons it was chosen, and how sure it is.

    Policies make decisions; :meth:`Sequencer.decide <opportune.sequencer.Sequencer.decide>` returns them.

    Parameters
    ----------
    action : Action
        The action.
    rule : str
        Which rule applied, in words.
    candidates : tuple of Candidate, default ()
        Every installable candidate (best first) with the options each keeps.
    positions : tuple of (str, Fraction), default ()
        The expected positions (1 = next) of the visible parts that decided a buffer choice.
    note : str, default ""
        More about the choice.
    exact : bool, default True
        Whether the rule was applied to exact numbers.
    method : str, default "exact"
        When the exact numbers did not fit the decision budget, the estimate used (e.g. ``"mcmc"``).
    estimates : tuple of Estimate, default ()
        Each candidate's estimated share of completions or expected position, with its standard
        error.
    confidence : float, default 1.0
        The estimated probability that the action is the one the exact rule would choose.
    seconds : float, default 0.0
        The time the decision took.
    close : bool, default False
        The estimate stopped on a near tie, being at least :data:`~opportune.engine.tuning.SURE` sure that
        no other candidate is better by more than :data:`~opportune.engine.tuning.INDIFFERENT`; that is then
        what the decision states.

    Examples
    --------
    >>> from opportune import make_plan, Sequencer
    >>> decision = Sequencer(make_plan(["a", "b", "c"], {"c": ["a", "b"]})).decide(["a", "b"])
    >>> decision.action, decision.exact, [c.part for c in decision.candidates]
    (Action(kind='install', part='a', source='bin'), True, ['a', 'b'])
    """

    action: Action
    rule: str
    candidates: tuple[Candidate, ...] = ()
    positions: tuple[tuple[str, Fraction], ...] = ()
    note: str = ""
    exact: bool = True
    method: str = "exact"
    estimates: tuple[Estimate, ...] = ()
    confidence: float = 1.0
    seconds: float = 0.0
    close: bool = False

    def explain(self, count=None) -> str:
        """The reasons in words, as ``--explain`` prints them.

        Parameters
        ----------
        count : callable, optional
            Writes a count (an int) as text: exactly (``str``, the default), or for people (the service
            passes :func:`~opportune.policies.printable.count_label`: ``6.13e98``).  With it, an
            expected position's exact fraction is given only where both its terms are written
            exactly (no ``e`` in their text).

        Returns
        -------
        str
            One line for the action and its rule, one per candidate or visible part, and for an
            estimated decision one saying how sure it is (:meth:`certainty`).

        Examples
        --------
        >>> d = Decision(Action("install", "a", "bin"), "keep the most options",
        ...              (Candidate("a", "bin", 40320, 10 ** 99, 1.0),))
        >>> print(d.explain(count=lambda n: f"{n:,}" if n < 10 ** 15 else f"{n:.2e}".replace("+", "")))
        install a: keep the most options
          candidate a from bin: keeps 40,320 of 1.00e99 completions, cost 1
        """
        write = str if count is None else count
        lines = [f"{self.action}: {self.rule}" + (f" ({self.note})" if self.note else "")]
        for c in self.candidates:
            src = "bin" if c.source == "bin" else f"buffer #{c.buffered_at + 1}"
            of = f" of {write(c.total)}" if c.total is not None else ""
            lines.append(f"  candidate {c.part} from {src}: keeps {write(c.options)}{of} completions, cost {c.cost:g}")
        for part, pos in self.positions:
            exact = str(pos) if count is None else f"{count(pos.numerator)}/{count(pos.denominator)}"
            shown = f" ({exact})" if count is None or "e" not in exact else ""
            lines.append(f"  visible {part}: expected position {float(pos):.3f}{shown}")
        for e in self.estimates:
            if e.kind == "share":
                lines.append(f"  candidate {e.part}" + (f" from {e.source}" if e.source else "")
                             + f": keeps ~{100 * e.value:.2f}% ± {100 * e.se:.2f}% of completions (estimated)")
            elif e.kind == "slack":
                lines.append(f"  visible {e.part}: slack ~{e.value:.2f} ± {e.se:.2f} (expected position estimated)")
            else:
                lines.append(f"  visible {e.part}: expected position ~{e.value:.2f} ± {e.se:.2f} (estimated)")
        if not self.exact:
            lines.append(f"  estimated by {self.method} within the decision budget ({1000 * self.seconds:.0f} ms): "
                         + self.certainty())
        return "\n".join(lines)

    def certainty(self) -> str:
        """How sure an estimated decision is, in one statement: the near tie it stopped on (``close``),
        or the estimated probability that it is the exact rule's choice ("exact" for an exact decision).

        Returns
        -------
        str
            ``"93.0% sure this is the exact rule's choice"``, or for a near tie ``"a near tie: over 99.9%
            sure that no other candidate is better by more than 1% of its share of completions"``.

        Examples
        --------
        >>> Decision(Action("buffer", "a"), "buffer", exact=False, method="mcmc", confidence=0.93).certainty()
        "93.0% sure this is the exact rule's choice"
        >>> Decision(Action("buffer", "a"), "buffer", exact=False, method="mcmc", confidence=0.99997).certainty()
        "over 99.9% sure this is the exact rule's choice"
        """
        if self.exact:
            return "exact"
        if self.close:
            of = ("of its share of completions" if any(e.kind == "share" for e in self.estimates)
                  else "of the steps remaining")
            return (f"a near tie: at least {100 * SURE:g}% sure that no other candidate is better by more than "
                    f"{100 * INDIFFERENT:g}% {of}")
        # an estimate is never certain: past 99.9% it says so rather than rounding to 100.0%
        sure = f"{100 * self.confidence:.1f}%" if self.confidence < 0.9995 else "over 99.9%"
        return f"{sure} sure this is the exact rule's choice"

    def to_dict(self) -> dict:
        """The decision as JSON values.

        An exact decision's dict depends only on the state and the look (no timing in it), so replays
        and stored answers compare equal.

        Returns
        -------
        dict
            ``action``, ``rule``, ``note``, ``candidates``, ``positions``, ``exact`` and ``method``; an
            estimated decision adds ``estimates``, ``confidence``, ``close`` and ``seconds``.

        Examples
        --------
        >>> Decision(Action("shake"), "nothing fits").to_dict()
        {'action': {'kind': 'shake', 'part': None, 'source': None}, 'rule': 'nothing fits', 'note': '', 'candidates': [], 'positions': [], 'exact': True, 'method': 'exact'}
        """
        out = {
            "action": self.action.to_dict(),
            "rule": self.rule,
            "note": self.note,
            "candidates": [c.to_dict() for c in self.candidates],
            "positions": [{"part": p, "expected": float(v), "exact": str(v)} for p, v in self.positions],
            "exact": self.exact,
            "method": self.method,
        }
        if not self.exact:
            out.update(estimates=[e.to_dict() for e in self.estimates], confidence=self.confidence,
                       close=self.close, seconds=round(self.seconds, 6))
        return out

    @classmethod
    def recorded(cls, d: dict) -> "Decision":
        """An estimated decision as :meth:`to_dict` recorded it.

        Its action, rule and estimates; the exact candidates and positions, which such a decision never
        has, are not restored.  Earlier versions wrote a near tie into the note (``stopped early:
        ...``): read as ``close``.

        Parameters
        ----------
        d : dict
            What :meth:`to_dict` wrote.

        Returns
        -------
        Decision
            An estimated decision (``exact=False``).

        Raises
        ------
        KeyError
            If ``d`` has no ``action``, or an estimate lacks a field.

        Examples
        --------
        >>> d = Decision(Action("buffer", "a"), "buffer", exact=False, method="mcmc", confidence=0.9)
        >>> Decision.recorded(d.to_dict()) == d
        True
        """
        note, close = d.get("note", ""), d.get("close", False)
        if "close" not in d and _OLD_NEAR_TIE in note:
            close = True
            note = "; ".join(n for n in note.split("; ") if not n.startswith(_OLD_NEAR_TIE))
        return cls(Action.from_dict(d["action"]), d.get("rule", ""), note=note, exact=False,
                   method=d.get("method", "estimate"),
                   estimates=tuple(Estimate(e["part"], e["kind"], e["value"], e["se"], e.get("source"))
                                   for e in d.get("estimates", ())),
                   confidence=d.get("confidence", 0.0), seconds=d.get("seconds", 0.0), close=close)


class DecidesOnMasks:
    """Mixin for a policy whose action depends only on the machine form of a state.

    Such a policy defines ``choose_at(engine, mask, consistent, buffer, free, visible)``:
    the engine's installed-units mask and consistent strategies, the buffer, its free
    locations and the look.  A simulation calls it directly, with no
    :class:`~opportune.sequencer.State` per look; :meth:`choose` adapts a ``State`` to it,
    and the policy's ``decide`` adds the reasons, so every world takes the same decision.
    Inside the package the six travel as one :class:`~opportune.policies.look.LookState`
    (:meth:`choose_look`).

    ``uses_buffer_order``: whether the action depends on the order of ``buffer`` (the order of
    buffering, as the sequencer keeps it), not only on its contents.  The exact evaluation
    (:class:`~opportune.policies.evaluate.PolicyEvaluator`) then keeps that order in its states.
    """

    uses_buffer_order = False

    def choose(self, state: State, visible: tuple[str, ...]) -> Action:
        """The action alone (what ``decide`` decides, without building its reasons)."""
        sched = state.schedule
        return self.choose_at(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)

    def choose_look(self, look) -> Action:
        """``choose_at`` on a :class:`~opportune.policies.look.LookState` (the six as one value): what the
        rules that fall back on another policy call; a policy that takes the value itself overrides it."""
        return self.choose_at(*look)

    def choose_looks(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                     looks) -> list[Action]:
        """``choose_at`` at one state on each of ``looks``, in order: what the exact evaluation asks
        (:meth:`PolicyEvaluator.policy_moves_at <opportune.policies.evaluate.PolicyEvaluator.policy_moves_at>`);
        a policy whose work at a state serves all its looks overrides it."""
        return [self.choose_at(engine, mask, consistent, buffer, free, visible) for visible in looks]


@runtime_checkable
class Policy(Protocol):
    """Chooses the next action: what the sequencer, the simulation and the service ask.

    Any object with a ``name`` and a ``decide(state, visible)`` method is a policy;
    :func:`~opportune.policies.named.make_policy` makes the package's by name.

    Examples
    --------
    >>> from opportune.policies.named import make_policy
    >>> isinstance(make_policy("paper"), Policy)
    True
    """

    name: str

    def decide(self, state: State, visible: tuple[str, ...]) -> Decision:
        """The next action for a look, with its reasons.  Must not change ``state``.

        Parameters
        ----------
        state : State
            The sequencer's state (:class:`opportune.sequencer.State`).
        visible : tuple of str
            The look: the part ids seen in the bin now, with repeats for several visible units of one
            part, already checked against the state.

        Returns
        -------
        Decision
            The action and why.

        Examples
        --------
        >>> from opportune import make_plan, Sequencer
        >>> from opportune.policies.named import make_policy
        >>> seq = Sequencer(make_plan(["a", "b"], {"b": ["a"]}))
        >>> make_policy("paper").decide(seq.state, ("b",)).action
        Action(kind='buffer', part='b', source=None)
        """


_gc_lock = threading.Lock()
_gc_pausers = 0
_gc_was_enabled = False


def pause_collector() -> None:
    """Pause Python's cyclic garbage collector until the matching :func:`resume_collector` (pauses
    nest, and count across threads).  Allocates nothing: an allocation may start a collection, so a
    decision calls this first and :func:`resume_collector` last, after its answer is built, and the
    collection that waited runs at the caller's next allocation, after the decision (with the pause
    in a ``with`` block it ran in the block's own exit, inside the decision; docs/decisions.md gives
    what a collection costs there)."""
    global _gc_pausers, _gc_was_enabled
    _gc_lock.acquire()      # a method call, not ``with``: entering a block allocates
    try:
        if _gc_pausers == 0:
            _gc_was_enabled = gc.isenabled()
            gc.disable()
        _gc_pausers += 1
    finally:
        _gc_lock.release()


def resume_collector() -> None:
    """End one :func:`pause_collector`; the last one re-enables the collector if it was on."""
    global _gc_pausers
    _gc_lock.acquire()
    try:
        _gc_pausers -= 1
        if _gc_pausers == 0 and _gc_was_enabled:
            gc.enable()
    finally:
        _gc_lock.release()


@contextmanager
def collector_paused():
    """Within the block, Python's cyclic garbage collector does not run; it runs at the first
    allocation after the last of the (possibly nested or concurrent) blocks ends.

    A budgeted decision runs in one (:func:`pause_collector`, which this block uses): a full
    collection walks every object of the process (the memos of a large plan are millions), and one
    landing inside a decision can take longer than the whole budget (docs/decisions.md states the
    measured cost).  Paused, it runs between looks
    instead, where a cell has seconds to spare.  The pause is as long as the decision, so what it
    lets pile up is bounded by the budget.  The order engine holds back its own upkeep (memo
    eviction, cache trimming) the same way: :meth:`opportune.engine.OrderEngine.deciding`, done by
    :meth:`~opportune.engine.OrderEngine.maintain` after each outcome.
    """
    pause_collector()
    try:
        yield
    finally:
        resume_collector()
