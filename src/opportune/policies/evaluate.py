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

The buffer's order.  A policy that declares ``uses_buffer_order`` (the paper's rule and its variants:
among equally good buffered candidates, the part buffered longest first) is scored on states that keep
the buffer as the running :class:`~opportune.sequencer.Sequencer` keeps it: in the order of buffering,
an installation taking the part's first location.  So the value is that of the rule `simulate` and the
sequencer run, not of a rule breaking that tie by declaration order (on a five-part plan with a part
of two units, 1 visible and 2 locations, the two differ by 0.006).  The order is kept only between
the pairs of parts the policy says can tie (``buffer_ties_at``, over every reachable state): buffers
that differ elsewhere share one state.  Other policies, and the optimum, keep the buffer as counts
per part.  How many states the policy may need is known before the work: the optimum's count
(:func:`~opportune.policies.states.estimate_states`) times the orders of a buffer that differ in those
pairs (:meth:`PolicyEvaluator.states_bound`).

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

import heapq

from opportune.engine import tuning
from opportune.policies.optimal import (
    OptimalSolver,
    OptimalTooLarge,
    OutOfTime,
    check_evaluable,
    compiled_optimal_available,
    optimal_solver,
)
from opportune.policies.states import orderings_factor, reachable_keys

__all__ = ["BufferOrder", "OutOfTime", "PolicyEvaluator", "PolicyStuck"]


class PolicyStuck(RuntimeError):
    """The policy shakes at every look of some state it reaches: it never finishes."""


class BufferOrder:
    """The states of a policy's programme, with the buffer in the order of buffering where the policy uses it.

    For :class:`PolicyEvaluator` and the pile's :class:`~opportune.policies.pile.PileSolver` (both
    :class:`OptimalSolver`): call :meth:`_keep_order` with the policy (None: the optimum) in ``__init__``.
    See the module's docstring.
    """

    def _keep_order(self, policy) -> None:
        #: The policy's states keep the buffer in the order of buffering (see the module's docstring).
        self.ordered = bool(getattr(policy, "uses_buffer_order", False))
        self._ties: set | None = set()
        self._listing = None            # the reachable states still to list for the ties (None: all listed)
        self._ties_known = False

    #: :attr:`ties` lists at most this many (installed, strategies) states; past it any pair's order may decide.
    TIES_MAX_KEYS = tuning.TIES_MAX_KEYS

    @property
    def ties(self) -> set | None:
        """The pairs of parts (declaration indices) whose order in the buffer the states keep: the union of
        the policy's ``buffer_ties_at`` over the reachable (installed, strategies) states (None: every pair,
        where the policy does not say, or past :attr:`TIES_MAX_KEYS` states).  Listed once, before the first
        state, within the ``deadline``: past it :class:`OutOfTime`, and a later call goes on from there."""
        if not self._ties_known:
            at = getattr(self.policy, "buffer_ties_at", None)
            if self._listing is None:
                self._listing = enumerate(reachable_keys(self.engine))
            for n, (mask, cons) in self._listing:
                if n >= self.TIES_MAX_KEYS:
                    self._ties = None
                    break
                pairs = None if at is None else at(self.engine, mask, cons)
                if pairs is None:
                    self._ties = None
                    break
                self._ties.update(pairs)
                if self._until.expired():
                    raise OutOfTime("listing where the buffer's order decides passed its deadline")
            self._ties_known, self._listing = True, None
        return self._ties

    def policy_key(self, mask: int, consistent: int, buffer) -> tuple:
        """The policy's key for a state: ``(mask, strategies, buffer)``, the buffer as part indices in the
        order of buffering if the policy uses it (:attr:`ordered`), else as counts per part.  O(buffer).

        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> PolicyEvaluator(OrderEngine(make_plan(["a", "b"], {})), Opportunistic()).policy_key(0, 1, ("b", "a"))
        (0, 1, (1, 0))
        """
        if not self.ordered:
            return super().policy_key(mask, consistent, buffer)
        return (mask, consistent, self._canonical(tuple(self.plan.index(p) for p in buffer)))

    def _canonical(self, order: tuple[int, ...]) -> tuple[int, ...]:
        """One representative of the buffers that differ from ``order`` only between parts whose order
        never decides (not a pair of :attr:`ties`): the least by declaration index of the orders that keep
        every tied pair as it is (a topological sort, least first).  Equal representatives mean equal
        decisions, now and after any move.  O(buffer²)."""
        n = len(order)
        if n < 2:
            return order
        ties = self.ties
        if ties is None:
            return order
        waits = [0] * n
        after: list[list[int]] = [[] for _ in range(n)]
        for j in range(1, n):
            b = order[j]
            for i in range(j):
                a = order[i]
                if (a, b) in ties or (b, a) in ties:
                    waits[j] += 1
                    after[i].append(j)
        ready = [(order[i], i) for i in range(n) if not waits[i]]
        heapq.heapify(ready)
        out = []
        while ready:
            part, i = heapq.heappop(ready)
            out.append(part)
            for j in after[i]:
                waits[j] -= 1
                if not waits[j]:
                    heapq.heappush(ready, (order[j], j))
        return tuple(out)

    def policy_moves(self, key: tuple, look: tuple[int, ...]):
        """The moves of :meth:`_moves` between the policy's keys: with an ordered buffer a buffered part
        goes last, and an installation from the buffer takes the part's first location, as in
        :meth:`Sequencer.report <opportune.sequencer.Sequencer.report>`.  O(parts) per move."""
        if not self.ordered:
            yield from self._moves(key, look)
            return
        mask, cons, order = key
        for cost, nxt, action in self._moves((mask, cons, self._counts(order)), look):
            if action.kind == "buffer":
                yield cost, (mask, cons, self._canonical(order + (self.plan.index(action.part),))), action
            elif action.source == "buffer":
                i = order.index(self.plan.index(action.part))
                yield cost, (nxt[0], nxt[1], self._canonical(order[:i] + order[i + 1:])), action
            else:
                yield cost, (nxt[0], nxt[1], order), action

    def _counts(self, order: tuple[int, ...]) -> tuple[int, ...]:
        """Units buffered per part (the optimum's form) from an ordered buffer."""
        buf = [0] * len(self.ids)
        for i in order:
            buf[i] += 1
        return tuple(buf)

    def _buffered(self, key: tuple) -> tuple[str, ...]:
        if not self.ordered:
            return super()._buffered(key)
        return tuple(self.ids[i] for i in key[2])

    def states_bound(self, optimum_states: int) -> int:
        """At most how many states the policy's programme stores, given the optimum's count (from
        :func:`~opportune.policies.states.estimate_states`): as many for the order-free key (the policy
        reaches a subset of the optimum's states), times the orders of a buffer content that differ in
        :attr:`ties` for the ordered one (:func:`~opportune.policies.states.orderings_factor`).
        Finds :attr:`ties` if not yet known.

        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> PolicyEvaluator(OrderEngine(make_plan(["a", "b", "c"], {})), Opportunistic()).states_bound(100)
        600
        """
        if not self.ordered:
            return optimum_states
        return optimum_states * orderings_factor(self.engine, self.capacity, self.ties)

    def policy_start(self) -> tuple:
        """The policy's key of the start."""
        return self.policy_key(0, self.engine.all_strategies, ())

    def _counts_key(self, key: tuple) -> tuple:
        """The optimum's form of a policy's key (the buffer as counts), for the looks of its bin."""
        return (key[0], key[1], self._counts(key[2])) if self.ordered else key


class PolicyEvaluator(BufferOrder, OptimalSolver):
    """Exact expected cost of a deterministic policy (one deciding by ``choose_at``) in a Markov bin.

    :func:`~opportune.policies.states.estimate_states` says how many states the optimum needs; a
    policy that ignores the buffer's order reaches at most as many, one that uses it
    (:attr:`ordered`) at most :meth:`states_bound` of them.
    Complexity: O(states × looks × one decision of the policy).

    Parameters
    ----------
    engine : OrderEngine
        The plan's engine.
    policy : Policy
        A deterministic policy with ``choose_at`` (:func:`~opportune.policies.named.make_policy`).
    **settings
        The bin and costs of :class:`~opportune.policies.optimal.OptimalSolver`, whose looks and
        moves it shares: ``visible`` (2), ``capacity`` (None: unlimited), ``costs`` (a
        :class:`~opportune.planning.costs.TimeModel`), ``weights`` (a weighted bin's visibilities)
        and ``max_states`` (the states visited, :class:`OptimalTooLarge` above it).

    Raises
    ------
    ValueError
        If the policy chooses at random or does not decide on the state alone (no ``choose_at``).

    Examples
    --------
    >>> from opportune import make_plan
    >>> from opportune.engine import OrderEngine
    >>> from opportune.policies.opportunistic import Opportunistic
    >>> evaluator = PolicyEvaluator(OrderEngine(make_plan(["a", "b", "c"], {"c": ["a", "b"]})), Opportunistic(),
    ...                             visible=1)
    >>> round(evaluator.value(), 4), round(evaluator.optimal(), 4), evaluator.policy_states
    (3.6667, 3.6667, 9)
    """

    def __init__(self, engine, policy, **settings):
        super().__init__(engine, **settings)
        check_evaluable(policy)
        self.policy = policy
        self._keep_order(policy)
        self._policy_values: dict[tuple, float] = {}
        self._optimum: OptimalSolver | None = None     # the compiled optimum, once asked for (None: this memo)
        #: The policy's value was the optimum's (:meth:`value`): it decides by the optimum in this bin.
        self.by_optimum = False
        #: States the policy's own memo may hold (:class:`OptimalTooLarge` above it); None: ``max_states``,
        #: which bounds the optimum's programme either way (``opportune evaluate`` sizes each by its speed).
        self.max_policy_states: int | None = None
        #: Whether :meth:`optimal` solves the plan with its interchangeable parts merged
        #: (:func:`~opportune.policies.optimal.optimal_solver`: fewer states, the same values to rounding; the
        #: compiled programme codes a state in 64 bits, which a plan of 45 distinct parts' buffers fills past
        #: 2^19 (installed, strategies) pairs): ``opportune evaluate`` sizes it on
        #: :func:`~opportune.policies.optimal.optimum_engine`.  False: on the plan as declared, whose states
        #: bound the policy's.
        self.merge_optimum = False

    #: Whether :meth:`value` takes the optimum's value for a policy that decides by the optimum in this bin
    #: (the look-ahead where its programme is the optimum's) instead of evaluating it look by look: the
    #: same value to the last ulps (tests/test_optimal_compiled.py checks both ways agree), and far sooner
    #: than the look-by-look evaluation (every look of every state asks the policy).
    OPTIMUM_SHORTCUT = True

    #: Whether :meth:`value` asks the policy for all the looks of a state at once (:meth:`policy_moves_at`),
    #: or look by look, each move matched among the legal ones and its successor solved before the next look
    #: (as it did before: kept to measure the difference, ``benchmarks/bench_evaluate_looks.py``).  The same
    #: values to the bit either way (tests/test_evaluate_batch.py).
    LOOKS_AT_ONCE = True

    def value(self, key: tuple | None = None) -> float:
        """Expected remaining cost of the policy from a state.

        From the start, a policy that decides by the optimum in this bin (:meth:`takes_optimum`) is
        given the optimum's value.  The ``deadline`` and ``progress`` apply.

        Parameters
        ----------
        key : tuple, optional
            A state, as :meth:`policy_key` makes it; ``None``: the start.

        Returns
        -------
        float
            The expected cost (in the costs' units: moves and looks by default).

        Raises
        ------
        OptimalTooLarge
            If the policy reaches more than ``max_states`` states.
        OutOfTime
            If the ``deadline`` passes (the states finished stay memoised).
        PolicyStuck
            If the policy shakes at every look of some state it reaches (it never finishes).

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> # one part visible: a first (2 moves), or b first (buffer b, install a, install b: 3 moves)
        >>> PolicyEvaluator(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), Opportunistic(), visible=1).value()
        2.5
        """
        if key is None and self.takes_optimum():
            self.by_optimum = True
            return self.optimal()
        return self._deep(self._policy_value, self.policy_start() if key is None else key)

    def takes_optimum(self) -> bool:
        """Whether :meth:`value` from the start takes the optimum's value (:attr:`OPTIMUM_SHORTCUT`).

        The policy says it decides by the optimum in this bin (the look-ahead prepares its programme to
        tell, as its first decision would).  Then the policy reaches none of :meth:`states_bound`'s
        states.

        Returns
        -------
        bool
            True if the policy decides by the optimum here.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> PolicyEvaluator(OrderEngine(make_plan(["a", "b"], {})), Opportunistic()).takes_optimum()
        False
        """
        decides_by = getattr(self.policy, "decides_by_optimum", None)
        return bool(self.OPTIMUM_SHORTCUT and self.uniform and decides_by is not None
                    and decides_by(self.engine, self.visible, self.capacity, self.costs))

    def optimal(self) -> float:
        """The optimum from the start, for comparison (see :class:`OptimalSolver`).

        By the compiled programme where it takes the plan and bin (the same values, sooner:
        docs/decisions.md gives how much; its states are :attr:`states`), else by this evaluator's own
        memo.  The ``deadline`` and ``progress`` apply.

        Returns
        -------
        float
            The least expected cost of any online policy in this bin.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> PolicyEvaluator(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), Opportunistic(), visible=1).optimal()
        2.5
        """
        weights = None if self.uniform else dict(zip(self.ids, self.weights))
        if self._optimum is None and (self.merge_optimum or compiled_optimal_available(self.engine, weights)):
            # by default on the plan as declared (not merged): its states are those counted before the work,
            # which bound the policy's too
            self._optimum = optimal_solver(self.engine, visible=self.visible, capacity=self.capacity,
                                           merge=self.merge_optimum, costs=self.costs, weights=weights,
                                           max_states=self.max_states)
        if self._optimum is None:
            return OptimalSolver.value(self)
        self._optimum.deadline, self._optimum.progress = self.deadline, self.progress
        return self._optimum.value()

    @property
    def states(self) -> int:
        """States the optimum's programme stored (after :meth:`optimal`)."""
        return self._optimum.states if self._optimum is not None else len(self._values)

    def _after(self, key, look, action, nxt) -> float:
        return self._policy_value(nxt)

    def _after_shake(self, key) -> float:
        return self._policy_value(key)

    @property
    def policy_states(self) -> int:
        """States the policy reaches from the start (after :meth:`value`)."""
        return len(self._policy_values)

    def policy_moves_at(self, key: tuple, looks) -> list:
        """The policy's move at a state on each of ``looks``, in order: ``(cost, next key)`` as
        :meth:`policy_moves` gives it for the action the policy chooses, or None where it shakes.  The
        policy is asked once for all the looks (``choose_looks``, where it has one: the look-ahead decides
        by its fallback there without going through its programme at every look), and each move is made
        from its action directly.  O(looks × (a decision + parts)).

        Parameters
        ----------
        key : tuple
            A state, as :meth:`policy_key` makes it.
        looks : sequence of tuple of int
            Looks, as sorted part indices.

        Returns
        -------
        list of (float, tuple) or None
            One per look.

        Raises
        ------
        ValueError
            If the policy chooses a move that is not legal at the state.

        Examples
        --------
        >>> from opportune import make_plan
        >>> from opportune.engine import OrderEngine
        >>> from opportune.policies.opportunistic import Opportunistic
        >>> ev = PolicyEvaluator(OrderEngine(make_plan(["a", "b"], {"b": ["a"]})), Opportunistic(), visible=1)
        >>> ev.policy_moves_at(ev.policy_start(), [(0,), (1,)])     # a seen: installed; b seen: buffered
        [(1.0, (1, 1, ())), (1.0, (0, 1, (1,)))]
        """
        mask, cons, _ = key
        ids = self.ids
        buffer = self._buffered(key)
        free = float("inf") if self.capacity is None else self.capacity - len(buffer)
        visible = [tuple(ids[i] for i in look) for look in looks]
        choose_looks = getattr(self.policy, "choose_looks", None)
        if choose_looks is not None:
            actions = choose_looks(self.engine, mask, cons, buffer, free, visible)
        else:
            actions = [self.policy.choose_at(self.engine, mask, cons, buffer, free, v) for v in visible]
        return [None if action.kind == "shake" else self._move_of(key, look, action)
                for look, action in zip(looks, actions)]

    def _move_of(self, key: tuple, look: tuple[int, ...], action) -> tuple[float, tuple]:
        """``(cost, next key)`` of ``action`` at ``key`` on ``look``: the move of :meth:`policy_moves` whose
        action it is (tests/test_evaluate_memo.py checks they agree), made without listing the others.
        A move that is not legal there is a ``ValueError``.  O(parts)."""
        mask, cons, buf = key
        i = self.plan.index(action.part)
        from_buffer = action.kind == "install" and (action.source or "bin") == "buffer"
        held = buf.count(i) if self.ordered else buf[i]
        legal = held > 0 if from_buffer else i in look
        if legal and action.kind == "buffer":
            legal = self.capacity is None or (len(buf) if self.ordered else sum(buf)) < self.capacity
            nxt = None if not legal else (mask, cons, self._canonical(buf + (i,)) if self.ordered
                                          else buf[:i] + (buf[i] + 1,) + buf[i + 1:])
        elif legal and action.kind == "install":
            u = self.engine.next_unit(mask, i)
            after = 0 if u is None else self.engine.consistent_after(mask, cons, u)
            legal = after != 0
            if not from_buffer:
                rest = buf
            elif self.ordered:
                j = buf.index(i)
                rest = self._canonical(buf[:j] + buf[j + 1:])
            else:
                rest = buf[:i] + (buf[i] - 1,) + buf[i + 1:]
            nxt = (mask | 1 << u, after, rest) if legal else None
        else:
            legal = False
        if not legal:
            raise ValueError(f"the policy chose {action} at a state where it is not a legal move")
        return self.move[i], nxt

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
        most = self.max_states if self.max_policy_states is None else self.max_policy_states
        if stored >= most:
            raise OptimalTooLarge(f"evaluating the policy needs more than {most:,} states for this "
                                  "plan; raise the state limit, or estimate with `opportune simulate`")
        moved = 0.0           # Σ p (c + V(next)) over the looks on which the policy moves
        p_shake = 0.0
        looks = self._looks(self._bin_counts(self._counts_key(key)))
        if self.LOOKS_AT_ONCE:
            # every look's decision first, then the states they lead to: the policy's work at this state (a
            # window's table) is done while it is at hand, not again after a descent that displaced it
            moves = self.policy_moves_at(key, [look for look, _ in looks])
        else:       # lazily: each look's successor solved before the next look is asked
            moves = (self._policy_move(self.policy, key, look) for look, _ in looks)
        for (_, p), move in zip(looks, moves):
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
