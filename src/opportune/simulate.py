"""The old path of :mod:`opportune.study.simulate`: the same module, for imports written before it moved."""

import sys

from opportune.study import simulate

sys.modules[__name__] = simulate
