"""The old path of :mod:`opportune.study.simulate_products`: the same module, for imports written before it moved."""

import sys

from opportune.study import simulate_products

sys.modules[__name__] = simulate_products
