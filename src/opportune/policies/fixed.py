"""The paper's alternatives to opportunism (section 2), each following one fixed admissible sequence.

* :class:`Pallet` — eliminate uncertainty: the pallet presents parts in the planned sequence.
* :class:`ShakeUntilVisible` — reduce uncertainty: install the next part when it is visible, otherwise shake.
* :class:`Kitting` — restore certainty: lay every part out first, then assemble in the fixed sequence.
* :class:`BufferFixed` — the "intelligent" restore of section 2.3: buffer a part only if the
  next part cannot be installed now.
* :class:`Quantify` — statistics of past runs pick the sequence; then as :class:`BufferFixed`.
"""

from __future__ import annotations

import random
from typing import Callable, Sequence

from opportune.engine import OrderEngine, Schedule
from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Decision, shared_action


def planned_sequence(plan_or_engine, prefer: Callable[[str], object] | None = None) -> tuple[str, ...]:
    """One admissible sequence: at each step the installable part first by ``prefer`` (default: declaration order).

    >>> from opportune import make_plan
    >>> planned_sequence(make_plan(["a", "b", "c"], {"a": ["c"]}))
    ('b', 'c', 'a')
    """
    s = Schedule(plan_or_engine)
    out = []
    while not s.is_complete:
        options = s.installable()
        part = min(options, key=prefer) if prefer else options[0]
        out.append(part)
        s = s.install(part)
    return tuple(out)


class FixedSequencePolicy(DecidesOnMasks):
    """Common ground: a fixed admissible sequence and the part it needs next."""

    name = "fixed"
    deterministic = True

    def __init__(self, sequence: Sequence[str]):
        self.sequence = tuple(sequence)
        self._rank = {}
        for i, p in enumerate(self.sequence):
            self._rank.setdefault(p, i)

    def next_part(self, state) -> str:
        return self.sequence[len(state.installed)]

    def earliest(self, parts) -> str:
        return min(parts, key=self._rank.__getitem__)

    def decide(self, state, visible) -> Decision:
        """:meth:`~opportune.policies.base.DecidesOnMasks.choose`'s action with the reason :meth:`reason` gives it."""
        action = self.choose(state, visible)
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        return Decision(action, self.reason(action, self.next_part(state), visible))

    def reason(self, action: Action, nxt: str, visible) -> str:
        """Why ``action`` (not ``done``), the sequence's next part being ``nxt``."""
        raise NotImplementedError


class ShakeUntilVisible(FixedSequencePolicy):
    """Reduce uncertainty: a fixed sequence; install the next part when visible, otherwise shake."""

    name = "shake"

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state (see :class:`~opportune.policies.base.DecidesOnMasks`); :meth:`decide`
        adds the reasons.  The next part is the sequence's entry after the installed units."""
        if mask == engine.full:
            return DONE
        nxt = self.sequence[mask.bit_count()]
        return shared_action("install", nxt, "bin") if nxt in visible else SHAKE

    def reason(self, action: Action, nxt: str, visible) -> str:
        if action.kind == "install":
            return f"'{nxt}' is next in the fixed sequence and visible"
        return f"'{nxt}' is next in the fixed sequence and not visible: shake"


class Pallet(ShakeUntilVisible):
    """Eliminate uncertainty: parts arrive on a pallet in the planned sequence (no vision, no shakes).
    Run it in a :class:`~opportune.worlds.PalletWorld`; the cost of the fixtures is outside the model."""

    name = "pallet"


class Kitting(FixedSequencePolicy):
    """Restore certainty: move every part from the bin to its own layout location, then assemble
    in the fixed sequence (exactly two motions per unit)."""

    name = "kitting"

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state; units still in the bin are those neither
        installed nor laid out."""
        if mask == engine.full:
            return DONE
        installed = mask.bit_count()
        if installed + len(buffer) < engine.n_units:
            return shared_action("buffer", self.earliest(visible)) if visible else SHAKE
        return shared_action("install", self.sequence[installed], "buffer")

    def reason(self, action: Action, nxt: str, visible) -> str:
        if action.kind == "buffer":
            return "lay every part out before assembling"
        if action.kind == "shake":
            return "parts remain in the bin but none is visible"
        return "all parts laid out: assemble in the fixed sequence"


class BufferFixed(FixedSequencePolicy):
    """Section 2.3's intelligent restore: a fixed sequence, buffering a part only if the next
    part cannot be installed now; shake when nothing is visible or the buffer is full."""

    name = "buffer"

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state (see :class:`~opportune.policies.base.DecidesOnMasks`)."""
        if mask == engine.full:
            return DONE
        nxt = self.sequence[mask.bit_count()]
        if nxt in buffer:
            return shared_action("install", nxt, "buffer")
        if nxt in visible:
            return shared_action("install", nxt, "bin")
        if visible and free > 0:
            return shared_action("buffer", self.earliest(visible))
        return SHAKE

    def reason(self, action: Action, nxt: str, visible) -> str:
        if action.kind == "install":
            where = "waiting in the buffer" if action.source == "buffer" else "visible"
            return f"'{nxt}' is next and {where}"
        if action.kind == "buffer":
            return f"'{nxt}' is next but not here: buffer the visible part needed first"
        return f"'{nxt}' is next and not visible" + (", buffer full" if visible else "")


class Quantify(BufferFixed):
    """Quantify uncertainty: learn from training runs the order in which parts tend to appear,
    follow the admissible sequence that best matches it, buffer on deviation.

    The sequence is built greedily: among the parts installable next, the one first seen
    earliest on average in the training runs (ties: declaration order).
    """

    name = "quantify"

    def __init__(self, engine: OrderEngine, mean_rank: dict[str, float], training_runs: int):
        order = {p: i for i, p in enumerate(engine.plan.part_ids)}
        sequence = planned_sequence(engine, prefer=lambda p: (mean_rank.get(p, float("inf")), order[p]))
        super().__init__(sequence)
        self.mean_rank = mean_rank
        self.training_runs = training_runs

    @classmethod
    def train(cls, engine: OrderEngine, world, runs: int = 200, seed: int = 0) -> "Quantify":
        """Watch ``runs`` training runs of the world — a robot taking a random visible unit at every
        look until the bin is empty — and record at which look each part was first seen."""
        units = [p.id for p in engine.plan.parts for _ in range(p.quantity)]
        totals = {p: 0.0 for p in engine.plan.part_ids}
        for run in range(runs):
            rng = random.Random(f"quantify-training:{seed}:{run}")
            world.reset(units, rng)
            first_seen: dict[str, int] = {}
            n_look = 0
            while len(world):
                look = world.look()
                for part in look:
                    first_seen.setdefault(part, n_look)
                n_look += 1
                if look:
                    world.take(look[rng.randrange(len(look))])
                else:
                    world.shake()
            for part, k in first_seen.items():
                totals[part] += k
        mean = {p: t / max(1, runs) for p, t in totals.items()}
        return cls(engine, mean, runs)
