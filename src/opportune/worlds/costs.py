"""The old path of :mod:`opportune.planning.costs`: the same module, for imports written before it moved."""

import sys

from opportune.planning import costs

sys.modules[__name__] = costs
