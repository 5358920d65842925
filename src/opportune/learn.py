"""The old path of :mod:`opportune.planning.learn`: the same module, for imports written before it moved."""

import sys

from opportune.planning import learn

sys.modules[__name__] = learn
