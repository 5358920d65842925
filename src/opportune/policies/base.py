"""What a policy sees and says: looks, actions, decisions and their reasons.

A *policy* is asked, at every look, for the next action given the state of the
cell.  The opportunistic policy of the paper, the alternatives it is compared
with (pallets, shaking, kitting, buffering, statistics) and the optimum all
implement the same :class:`Policy` interface, so the sequencer, the
simulation and the service share one decision path.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

if TYPE_CHECKING:  # pragma: no cover
    from opportune.sequencer import State

ActionKind = Literal["install", "buffer", "shake", "done"]
Source = Literal["bin", "buffer"]


@dataclass(frozen=True)
class Action:
    """One robot action: ``install`` a part (from the bin or a buffer location),
    ``buffer`` a visible part (bin → a free buffer location), ``shake`` the bin
    (and look again), or ``done``."""

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
        return {"kind": self.kind, "part": self.part, "source": self.source}

    @classmethod
    def from_dict(cls, d: dict) -> "Action":
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
    """A part that could be installed now, with what installing it keeps open."""

    part: str
    source: Source
    options: int          # admissible completions left after installing it
    total: int            # admissible completions now
    cost: float           # acquire + install
    buffered_at: int | None = None  # position in the buffer (0 = buffered longest)

    def to_dict(self) -> dict:
        return {"part": self.part, "source": self.source, "options": str(self.options),
                "total": str(self.total), "cost": self.cost, "buffered_at": self.buffered_at}


@dataclass(frozen=True)
class Decision:
    """An action with the reasons it was chosen.

    ``candidates`` lists every installable candidate (best first) with the
    options each keeps; ``positions`` the expected positions (1 = next) of the
    visible parts that decided a buffer choice; ``rule`` which rule applied.
    """

    action: Action
    rule: str
    candidates: tuple[Candidate, ...] = ()
    positions: tuple[tuple[str, Fraction], ...] = ()
    note: str = ""

    def explain(self) -> str:
        """The reasons in words, as ``--explain`` prints them."""
        lines = [f"{self.action}: {self.rule}" + (f" ({self.note})" if self.note else "")]
        for c in self.candidates:
            src = "bin" if c.source == "bin" else f"buffer #{c.buffered_at + 1}"
            lines.append(f"  candidate {c.part} from {src}: keeps {c.options} of {c.total} completions, cost {c.cost:g}")
        for part, pos in self.positions:
            lines.append(f"  visible {part}: expected position {float(pos):.3f} ({pos})")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "action": self.action.to_dict(),
            "rule": self.rule,
            "note": self.note,
            "candidates": [c.to_dict() for c in self.candidates],
            "positions": [{"part": p, "expected": float(v), "exact": str(v)} for p, v in self.positions],
        }


class DecidesOnMasks:
    """Mixin for a policy whose action depends only on the machine form of a state.

    Such a policy defines ``choose_at(engine, mask, consistent, buffer, free, visible)``:
    the engine's installed-units mask and consistent strategies, the buffer, its free
    locations and the look.  A simulation calls it directly, with no
    :class:`~opportune.sequencer.State` per look; :meth:`choose` adapts a ``State`` to it,
    and the policy's ``decide`` adds the reasons, so every world takes the same decision.
    """

    def choose(self, state: "State", visible: tuple[str, ...]) -> Action:
        """The action alone (what ``decide`` decides, without building its reasons)."""
        sched = state.schedule
        return self.choose_at(sched.engine, sched.mask, sched.consistent, state.buffer, state.buffer_free, visible)


@runtime_checkable
class Policy(Protocol):
    """Chooses the next action.  ``decide`` must not change ``state``.

    ``visible`` is the look: the part ids seen in the bin now, with repeats
    for several visible units of one part, already checked against the state.
    """

    name: str

    def decide(self, state: "State", visible: tuple[str, ...]) -> Decision: ...
