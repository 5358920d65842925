"""Planning: the plan (parts, strategies, constraints), several products in one plan, a strategy's order,
the cheapest relaxation of an over-constrained plan, and a plan learnt from observed sequences.

:mod:`~opportune.planning.plan` and :mod:`~opportune.planning.products` are the bottom layer (nothing of
files, nothing of counting); :mod:`~opportune.planning.relax` and :mod:`~opportune.planning.learn` build
plans with the order engine and the file readers, so they import those and nothing below imports them.
"""
