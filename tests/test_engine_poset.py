"""Poset: closure, union, minimal/maximal, down/up-sets, cover pairs and cycles vs brute force."""

from __future__ import annotations

import pickle
from itertools import product

import pytest
from hypothesis import given, settings, strategies as st

from opportune.engine.poset import CycleError, Poset, bits, elements

MAX_N = 8


def reach(n, pairs):
    """Brute-force transitive closure (Floyd–Warshall) as a set of pairs."""
    r = [[False] * n for _ in range(n)]
    for a, b in pairs:
        r[a][b] = True
    for k in range(n):
        for i in range(n):
            if r[i][k]:
                for j in range(n):
                    if r[k][j]:
                        r[i][j] = True
    return r


def has_cycle(n, pairs):
    r = reach(n, pairs)
    return any(r[i][i] for i in range(n))


@st.composite
def relations(draw, acyclic=True):
    """(n, pairs): a random relation; acyclic ones are drawn along a random permutation."""
    n = draw(st.integers(0, MAX_N))
    if n == 0:
        return 0, []
    if acyclic:
        perm = draw(st.permutations(range(n)))
        cand = [(perm[i], perm[j]) for i in range(n) for j in range(i + 1, n)]
    else:
        cand = [(i, j) for i in range(n) for j in range(n)]
    pairs = draw(st.lists(st.sampled_from(cand), max_size=14)) if cand else []
    return n, pairs


masks = st.integers(0, (1 << MAX_N) - 1)


@settings(max_examples=300, deadline=None)
@given(relations())
def test_closure_matches_brute_force(rel):
    n, pairs = rel
    p = Poset.from_pairs(n, pairs)
    r = reach(n, pairs)
    assert p.n == n and p.full == (1 << n) - 1
    for i in range(n):
        assert p.below[i] == sum(1 << j for j in range(n) if r[j][i])
        assert p.above[i] == sum(1 << j for j in range(n) if r[i][j])
        for j in range(n):
            assert p.less(i, j) == r[i][j]
            assert p.comparable(i, j) == (r[i][j] or r[j][i])
    # the same order from predecessor masks, from its own cover pairs, and with redundant pairs added
    preds = [0] * n
    for a, b in pairs:
        preds[b] |= 1 << a
    assert Poset.from_predecessors(preds) == p
    assert Poset.from_pairs(n, p.cover_pairs()) == p
    closed = [(i, j) for i in range(n) for j in range(n) if r[i][j]]
    q = Poset.from_pairs(n, closed)
    assert q == p and hash(q) == hash(p)
    assert pickle.loads(pickle.dumps(p)) == p
    assert p.dual().dual() == p


@settings(max_examples=300, deadline=None)
@given(relations())
def test_cover_pairs_are_the_transitive_reduction(rel):
    n, pairs = rel
    p = Poset.from_pairs(n, pairs)
    r = reach(n, pairs)
    expect = sorted(
        (a, b) for a in range(n) for b in range(n)
        if r[a][b] and not any(r[a][c] and r[c][b] for c in range(n))
    )
    assert p.cover_pairs() == expect


@settings(max_examples=300, deadline=None)
@given(relations(), masks)
def test_minimal_maximal_downset_upset(rel, mask):
    n, pairs = rel
    p = Poset.from_pairs(n, pairs)
    mask &= p.full
    r = reach(n, pairs)
    members = [i for i in range(n) if mask >> i & 1]
    mins = sum(1 << i for i in members if not any(r[j][i] for j in members))
    maxs = sum(1 << i for i in members if not any(r[i][j] for j in members))
    assert p.minimal(mask) == mins
    assert p.maximal(mask) == maxs
    down = all(not r[j][i] or mask >> j & 1 for i in members for j in range(n))
    up = all(not r[i][j] or mask >> j & 1 for i in members for j in range(n))
    assert p.is_downset(mask) == down
    assert p.is_upset(mask) == up
    dc, uc = p.down_closure(mask), p.up_closure(mask)
    assert p.is_downset(dc) and dc & mask == mask
    assert p.is_upset(uc) and uc & mask == mask
    assert p.is_downset(p.full & ~uc)   # complement of an up-set is a down-set


@settings(max_examples=300, deadline=None)
@given(relations(), relations())
def test_union_matches_brute_force(r1, r2):
    n = max(r1[0], r2[0])
    p1, p2 = Poset.from_pairs(n, r1[1]), Poset.from_pairs(n, r2[1])
    both = r1[1] + r2[1]
    if has_cycle(n, both):
        with pytest.raises(CycleError) as info:
            p1.union(p2)
        assert_real_cycle(info.value.cycle, set(both) | set(p1.cover_pairs()) | set(p2.cover_pairs()), n, both)
    else:
        u = p1.union(p2)
        assert u == Poset.from_pairs(n, both)
        assert u == p2.union(p1)


def assert_real_cycle(cycle, allowed_steps, n, pairs):
    """``cycle`` is closed, has >= 2 entries and each step is a relation that holds."""
    assert len(cycle) >= 2 and cycle[0] == cycle[-1]
    r = reach(n, pairs)
    for a, b in zip(cycle, cycle[1:]):
        assert (a, b) in allowed_steps or r[a][b]


@settings(max_examples=400, deadline=None)
@given(relations(acyclic=False))
def test_cycle_error_exactly_for_cyclic_relations(rel):
    n, pairs = rel
    if has_cycle(n, pairs):
        with pytest.raises(CycleError) as info:
            Poset.from_pairs(n, pairs)
        cyc = info.value.cycle
        assert isinstance(info.value, ValueError)
        assert len(cyc) >= 2 and cyc[0] == cyc[-1]
        # every step of the reported cycle is one of the given pairs
        assert all((a, b) in set(pairs) for a, b in zip(cyc, cyc[1:]))
        assert len(set(cyc[:-1])) == len(cyc) - 1      # a simple cycle
        preds = [0] * n
        for a, b in pairs:
            preds[b] |= 1 << a
        with pytest.raises(CycleError):
            Poset.from_predecessors(preds)
    else:
        Poset.from_pairs(n, pairs)


def test_cycle_examples():
    with pytest.raises(CycleError) as info:
        Poset.from_pairs(3, [(1, 2), (2, 1)])
    assert info.value.cycle == [1, 2, 1]
    with pytest.raises(CycleError) as info:
        Poset.from_pairs(3, [(0, 0)])
    assert info.value.cycle == [0, 0]
    with pytest.raises(CycleError) as info:
        Poset.from_predecessors([0b100, 0b1, 0b10])
    assert info.value.cycle == [0, 1, 2, 0]
    assert "0 -> 1 -> 2 -> 0" in str(info.value)


def test_bad_input():
    with pytest.raises(ValueError):
        Poset.from_pairs(2, [(0, 2)])
    with pytest.raises(ValueError):
        Poset.from_pairs(2, [(-1, 0)])
    with pytest.raises(ValueError):
        Poset.from_predecessors([0b100, 0])
    with pytest.raises(ValueError):
        Poset.from_pairs(2, []).union(Poset.from_pairs(3, []))
    p = Poset.from_pairs(2, [(0, 1)])
    with pytest.raises(AttributeError):
        p.n = 3
    assert {p: 1}[Poset.from_predecessors([0, 1])] == 1


def test_helpers_and_constructors():
    assert list(bits(0)) == [] and elements(0b1010) == [1, 3]
    assert Poset.chain(4) == Poset.from_pairs(4, [(0, 1), (1, 2), (2, 3)])
    assert Poset.antichain(3) == Poset.from_pairs(3, [])
    assert Poset.from_pairs(0, []).full == 0
    q, old = Poset.from_pairs(4, [(0, 1), (1, 2), (3, 2)]).restrict(0b1101)
    assert old == [0, 2, 3] and q == Poset.from_pairs(3, [(0, 1), (2, 1)])
    assert Poset.from_pairs(3, [(0, 1)]).with_pairs([(1, 2)]).less(0, 2)
    with pytest.raises(CycleError):
        Poset.from_pairs(3, [(0, 1)]).with_pairs([(1, 0)])


def test_large_closure():
    n = 400
    p = Poset.from_pairs(n, [(i, i + 1) for i in range(n - 1)])
    assert p.below[n - 1] == p.full >> 1 and p.above[0] == p.full - 1
    assert len(p.cover_pairs()) == n - 1
