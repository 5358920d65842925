"""Exact expected cost of a deterministic policy in a Markov bin: the yardstick for policies.

Under the ``uniform`` and ``weighted`` bin models a look depends only on what is in the bin, so
a deterministic policy turns the assembly into a Markov chain over states (installed parts,
buffered parts).  At a state *s* a look *L* arrives with probability *p(L)*; the policy either
moves (cost *c(a)*, to state *s'*) or shakes (cost ``c_shake``, back to *s*).  So

    V(s) = (c_look + Σ_moves p(L) (c(a) + V(s')) + P_shake c_shake) / (1 − P_shake)

which this module solves exactly by memoised recursion over the states the policy reaches (every
move installs or buffers a part, so the recursion terminates).  Beside it, the optimum of
:class:`~opportune.policies.optimal.OptimalSolver` gives the best any online policy can do, and
their ratio says how far the policy is from it — with no Monte Carlo error.

Example
-------
>>> from opportune import make_plan
>>> from opportune.engine import OrderEngine
>>> from opportune.policies.opportunistic import Opportunistic
>>> engine = OrderEngine(make_plan(["a", "b"], {"b": ["a"]}))
>>> # one part visible: a first (2 moves), or b first (buffer b, install a, install b: 3 moves)
>>> PolicyEvaluator(engine, Opportunistic(), visible=1).value()
2.5
"""

from __future__ import annotations

from opportune.policies.optimal import OptimalSolver, OptimalTooLarge, OutOfTime, check_evaluable

__all__ = ["OutOfTime", "PolicyEvaluator", "PolicyStuck"]


class PolicyStuck(RuntimeError):
    """The policy shakes at every look of some state it reaches: it never finishes."""


class PolicyEvaluator(OptimalSolver):
    """Exact expected cost of ``policy`` (deterministic, deciding by ``choose_at``).

    Takes the same bin and cost settings as :class:`OptimalSolver`, whose looks and moves it
    shares; ``max_states`` bounds the states visited (:class:`OptimalTooLarge` above it), ``deadline``
    the time (:class:`OutOfTime`); :func:`~opportune.policies.states.estimate_states` says how many
    states the optimum needs, and the policy reaches at most as many.
    Complexity: O(states × looks × one decision of the policy).
    """

    def __init__(self, engine, policy, **settings):
        super().__init__(engine, **settings)
        check_evaluable(policy)
        self.policy = policy
        self._policy_values: dict[tuple, float] = {}

    def value(self, key: tuple | None = None) -> float:
        """Expected remaining cost of the policy from a state (default: the start)."""
        return self._deep(self._policy_value, key)

    def optimal(self) -> float:
        """The optimum from the start, for comparison (see :class:`OptimalSolver`)."""
        return OptimalSolver.value(self)

    def _after(self, key, look, action, nxt) -> float:
        return self._policy_value(nxt)

    def _after_shake(self, key) -> float:
        return self._policy_value(key)

    @property
    def policy_states(self) -> int:
        """States the policy reaches from the start (after :meth:`value`)."""
        return len(self._policy_values)

    # ------------------------------------------------------------ internals

    def _policy_value(self, key: tuple) -> float:
        cached = self._policy_values.get(key)
        if cached is not None:
            return cached
        if key[0] == self.engine.full:
            self._policy_values[key] = 0.0
            return 0.0
        stored = len(self._policy_values)
        self._tick("the policy's evaluation", stored)
        if stored >= self.max_states:
            raise OptimalTooLarge(f"evaluating the policy needs more than {self.max_states:,} states for this "
                                  "plan; raise the state limit, or estimate with `opportune simulate`")
        moved = 0.0           # Σ p (c + V(next)) over the looks on which the policy moves
        p_shake = 0.0
        for look, p in self._looks(self._bin_counts(key)):
            move = self._policy_move(self.policy, key, look)
            if move is None:
                p_shake += p
            else:
                moved += p * (move[0] + self._policy_value(move[1]))
        if p_shake >= 1.0 - 1e-15:
            raise PolicyStuck(f"'{getattr(self.policy, 'name', 'the policy')}' shakes at every look of a state "
                              "it reaches: it never finishes there")
        v = (self.costs.look + moved + p_shake * self.costs.shake) / (1.0 - p_shake)
        self._policy_values[key] = v
        return v
