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

from fractions import Fraction

from opportune.policies.base import DONE, SHAKE, Action, DecidesOnMasks, Candidate, Decision, shared_action


def ranked_candidates(state, visible: tuple[str, ...]) -> list[tuple]:
    """Installable candidates best first, as ``(sort key, part, source, buffer position)``.

    The sort key is rule 1: most options, bin before buffer, lower cost,
    buffered longest, declaration order.  A part both visible and buffered is
    a candidate from each; a part buffered twice, from its first location.
    """
    buffer = state.buffer
    options = state.schedule.options_for((*visible, *buffer))  # the installable ones, with their options
    if not options:
        return []
    plan = state.plan
    out = []
    for part, n in options.items():  # only the installable ones: usually few, while the buffer can be long
        cost, index = plan.part(part).cost, plan.index(part)
        if part in visible:
            out.append(((-n, 0, cost, -1, index), part, "bin", None))
        if part in buffer:
            pos = buffer.index(part)
            out.append(((-n, 1, cost, pos, index), part, "buffer", pos))
    out.sort()
    return out


def buffer_choice(state, visible: tuple[str, ...]) -> list[tuple]:
    """Visible parts ranked by rule 2, as ``(expected position, declaration index, part)``."""
    total, ranked = _buffer_ranking(state, visible)
    return [(Fraction(s, total), index, part) for s, index, part in ranked]


def _buffer_ranking(state, visible: tuple[str, ...]) -> tuple[int, list[tuple]]:
    """Rule 2 on integers: ``(completions, [(position sum, declaration index, part), ...])``, best first.

    The expected positions are the sums over one denominator, the completions.
    """
    total, sums = state.schedule.position_sums_for(set(visible))
    plan = state.plan
    return total, sorted((s, plan.index(p), p) for p, s in sums.items())


class Opportunistic(DecidesOnMasks):
    """Install what keeps the most options; buffer what is needed earliest; shake last."""

    name = "opportunistic"
    deterministic = True

    @staticmethod
    def choose_at(engine, mask: int, consistent: int, buffer: tuple[str, ...], free: float,
                  visible: tuple[str, ...]) -> Action:
        """The action on the machine form of a state (see :class:`~opportune.policies.base.DecidesOnMasks`).

        The best candidate is the least sort key of :func:`ranked_candidates` (keys are distinct:
        a part's bin and buffer candidates differ in the source), found without sorting.
        """
        if mask == engine.full:
            return DONE
        asked = (*visible, *buffer)
        can = engine.installable_among(mask, consistent, asked)
        if len(can) == 1:  # one candidate part: nothing to compare, so nothing to count
            part = can[0]
            return shared_action("install", part, "bin" if part in visible else "buffer")
        if can:
            options = engine.options_for(mask, consistent, can)
            plan = engine.plan
            best = None
            for part, n in options.items():
                cost, index = plan.part(part).cost, plan.index(part)
                if part in visible:
                    key = (-n, 0, cost, -1, index, part, "bin")
                    if best is None or key < best:
                        best = key
                if part in buffer:
                    key = (-n, 1, cost, buffer.index(part), index, part, "buffer")
                    if best is None or key < best:
                        best = key
            return shared_action("install", best[5], best[6])
        if visible and free > 0:
            _, sums = engine.position_sums_for(mask, consistent, set(visible))
            plan = engine.plan
            return shared_action("buffer", min((s, plan.index(p), p) for p, s in sums.items())[2])
        return SHAKE

    @staticmethod
    def decision_key(engine, capacity):
        """A function of (installed mask, strategies, buffer, sorted look) whose equal values mean equal
        decisions — for caching decisions in simulations.  Only installable parts matter when there are
        candidates (with the buffered ones in buffer order, for the tie-break); otherwise the look and
        whether a buffer location is free."""
        installable = engine.installable_set

        def key(mask, cons, buffer, look):
            can = installable(mask, cons)
            in_look = can.intersection(look)  # a set: which candidate comes from the bin, not in what order
            in_buffer = tuple([p for p in buffer if p in can]) if buffer else ()
            if in_look or in_buffer:
                return (mask, cons, in_look, in_buffer)
            return (mask, cons, look, capacity is None or len(buffer) < capacity)

        return key

    def decide(self, state, visible: tuple[str, ...]) -> Decision:
        action = self.choose(state, visible)
        if action.kind == "done":
            return Decision(DONE, "the assembly is complete")
        if action.kind == "install":
            total = state.schedule.count()
            candidates = tuple(Candidate(part, source, -key[0], total, key[2], pos)
                               for key, part, source, pos in ranked_candidates(state, visible))
            return Decision(action, "install the candidate that keeps the most options", candidates)
        if action.kind == "buffer":
            ranked = buffer_choice(state, visible)
            return Decision(action, "nothing can be installed: buffer the visible part needed earliest",
                            positions=tuple((p, pos) for pos, _, p in ranked))
        why = "nothing visible" if not visible else "nothing installable and the buffer is full"
        return Decision(SHAKE, "shake", note=why)
