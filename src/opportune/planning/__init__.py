"""Planning: the plan (parts, strategies, constraints), several products in one plan, a strategy's order,
and the cell's costs: the bottom layer (nothing of files, nothing of counting).

Plans made by a tool rather than written by hand (learnt from observed sequences, relaxed from an
over-constrained plan, derived from the product's geometry) come from :mod:`opportune.derive`, which
sits above the file readers and the order engine.
"""
