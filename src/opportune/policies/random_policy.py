"""An ablation: opportunism without the least-commitment preferences."""

from __future__ import annotations

import random

from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Decision, shared_action


class RandomChoice(DecidesOnMasks):
    """Install a random installable candidate (visible or buffered); else buffer a random visible
    part if a location is free; else shake.  Seeded per trial through :meth:`start`."""

    name = "random"
    deterministic = False

    def __init__(self, seed: int = 0):
        self.rng = random.Random(seed)

    def start(self, rng: random.Random) -> None:
        self.rng = rng

    def choose_at(self, engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state (see :class:`~opportune.policies.base.DecidesOnMasks`).

        Candidates are drawn from a list in declaration order, bin before buffer, so a seed
        gives the same choices however the look is ordered.
        """
        if mask == engine.full:
            return DONE
        cands = []
        for part in engine.installable_among(mask, consistent, (*visible, *buffer)):  # declaration order
            if part in visible:
                cands.append((part, "bin"))
            if part in buffer:
                cands.append((part, "buffer"))
        if cands:
            part, source = cands[self.rng.randrange(len(cands))]
            return shared_action("install", part, source)
        if visible and free > 0:
            choices = sorted(set(visible), key=engine.plan.index)
            return shared_action("buffer", choices[self.rng.randrange(len(choices))])
        return SHAKE

    def decide(self, state, visible) -> Decision:
        action = self.choose(state, visible)
        if action.kind == "install":
            return Decision(action, "a random installable candidate")
        if action.kind == "buffer":
            return Decision(action, "a random visible part")
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        return Decision(SHAKE, "nothing installable")
