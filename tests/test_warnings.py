"""The suite prints no warning from our own code, and none can come back unseen: pyproject.toml's
filterwarnings makes a warning from opportune's modules (and Hypothesis's and Starlette's) an error.  The
source of the Hypothesis warnings it once printed: deep counts raised the recursion limit for good."""

from __future__ import annotations

import sys
import warnings

import pytest

from opportune.engine.count import Counter
from opportune.engine.downsets import count_downsets_bounded
from opportune.engine.poset import Poset


def test_a_warning_from_our_modules_is_an_error_in_the_suite():
    with pytest.raises(UserWarning, match="from the engine"):
        warnings.warn_explicit("from the engine", UserWarning, "count.py", 1, module="opportune.engine.count")
    # a module whose name only starts alike is not ours
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        warnings.warn_explicit("elsewhere", UserWarning, "x.py", 1, module="opportune_plugin")
    assert len(caught) == 1


@pytest.mark.parametrize("n", [3_000])
def test_a_deep_count_leaves_the_recursion_limit_as_it_found_it(n):
    """A chain of 3,000 elements recurses 3,000 deep: the count gets the room it needs, and gives it back."""
    chain = Poset.chain(n)
    before = sys.getrecursionlimit()
    assert before < 3 * n   # the count needs more than the limit in force
    assert Counter(chain).count() == 1
    assert Counter(chain).position_sums()[n - 1] == n
    assert count_downsets_bounded(chain) == n + 1
    assert sys.getrecursionlimit() == before
