"""The old path of :mod:`opportune.study.report`: the same module, for imports written before it moved."""

import sys

from opportune.study import report

sys.modules[__name__] = report
