"""An ablation: opportunism without the least-commitment preferences."""

from __future__ import annotations

import random

from opportune.policies.base import DONE, SHAKE, Action, Decision


class RandomChoice:
    """Install a random installable candidate (visible or buffered); else buffer a random visible
    part if a location is free; else shake.  Seeded per trial through :meth:`start`."""

    name = "random"
    deterministic = False

    def __init__(self, seed: int = 0):
        self.rng = random.Random(seed)

    def start(self, rng: random.Random) -> None:
        self.rng = rng

    def decide(self, state, visible) -> Decision:
        if state.is_complete:
            return Decision(DONE, "the assembly is complete")
        sched = state.schedule
        cands = sorted({(p, "bin") for p in visible if sched.can_install(p)}
                       | {(p, "buffer") for p in state.buffer if sched.can_install(p)},
                       key=lambda c: (state.plan.index(c[0]), c[1]))
        if cands:
            part, source = cands[self.rng.randrange(len(cands))]
            return Decision(Action("install", part, source), "a random installable candidate")
        if visible and state.buffer_free > 0:
            choices = sorted(set(visible), key=state.plan.index)
            return Decision(Action("buffer", choices[self.rng.randrange(len(choices))]), "a random visible part")
        return Decision(SHAKE, "nothing installable")
