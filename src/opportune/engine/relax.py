"""The old path of :mod:`opportune.planning.relax`: the same module, for imports written before it moved."""

import sys

from opportune.planning import relax

sys.modules[__name__] = relax
