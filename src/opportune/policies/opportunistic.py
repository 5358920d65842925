"""The paper's opportunistic policy (sections 3–4), made exact so results are reproducible.

At each look, the candidates are the installable parts among those visible
in the bin and those in buffer locations.

1. If there are candidates, install the one that leaves the most admissible
   completions.  Ties: a part visible in the bin before a buffered one (the bin
   opportunity may vanish at the next look; the buffer keeps), then the lower
   acquire + install cost, then among buffered parts the one buffered longest,
   then declaration order.
2. Else, if a part is visible and a buffer location is free, buffer the
   visible part needed earliest: the smallest expected position in a uniformly
   random admissible completion.  Ties: declaration order.
3. Else shake.
"""

from __future__ import annotations

from opportune.policies.base import DONE, SHAKE, Action, Candidate, Decision


def install_candidates(state, visible: tuple[str, ...]) -> list[Candidate]:
    """Every installable candidate (one per part and source), best first by the rule-1 order."""
    sched = state.schedule
    options = sched.options()
    if not options:
        return []
    total = sched.count()
    plan = state.plan
    out: list[Candidate] = []
    seen_bin = set()
    for part in visible:
        if part in options and part not in seen_bin:
            seen_bin.add(part)
            out.append(Candidate(part, "bin", options[part], total, plan.part(part).cost))
    seen_buf = set()
    for pos, part in enumerate(state.buffer):
        if part in options and part not in seen_buf:
            seen_buf.add(part)
            out.append(Candidate(part, "buffer", options[part], total, plan.part(part).cost, buffered_at=pos))
    out.sort(key=lambda c: (-c.options, c.source != "bin", c.cost,
                            c.buffered_at if c.buffered_at is not None else -1, plan.index(c.part)))
    return out


class Opportunistic:
    """Install what keeps the most options; buffer what is needed earliest; shake last."""

    name = "opportunistic"

    def decide(self, state, visible: tuple[str, ...]) -> Decision:
        if state.is_complete:
            return Decision(DONE, "the assembly is complete")
        candidates = install_candidates(state, visible)
        if candidates:
            best = candidates[0]
            return Decision(Action("install", best.part, best.source),
                            "install the candidate that keeps the most options", tuple(candidates))
        if visible and state.buffer_free > 0:
            positions = state.schedule.expected_positions()
            plan = state.plan
            ranked = sorted(set(visible), key=lambda p: (positions[p], plan.index(p)))
            return Decision(Action("buffer", ranked[0]), "nothing can be installed: buffer the visible part needed earliest",
                            positions=tuple((p, positions[p]) for p in ranked))
        why = "nothing visible" if not visible else "nothing installable and the buffer is full"
        return Decision(SHAKE, "shake", note=why)
