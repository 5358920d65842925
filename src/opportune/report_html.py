"""The old path of :mod:`opportune.study.report_html`: the same module, for imports written before it moved."""

import sys

from opportune.study import report_html

sys.modules[__name__] = report_html
