"""The old path of :mod:`opportune.planning.products`: the same module, for imports written before it moved."""

import sys

from opportune.planning import products

sys.modules[__name__] = products
