"""The policy lab's results file: how its lines are read back (benchmarks/policy_lab.py)."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import policy_lab  # noqa: E402

KEY = "0:8-12:r1-12:2:inf:pile:"


def _read(lines, cap=2_000_000):
    done: dict = {}
    for key, rec in lines:
        policy_lab._keep(done, key, dict(rec), cap)
    return done


def test_an_exact_result_stands_whatever_cap_it_ran_with():
    done = _read([(KEY + "2000000", {"skipped": "too many states"}),
                  (KEY + "3000000", {"gaps": {"lookahead": 0.0}, "optimum": 21.5, "states": 2_500_000})])
    assert done == {KEY + "2000000": {"gaps": {"lookahead": 0.0}, "optimum": 21.5, "states": 2_500_000}}


def test_a_skip_never_hides_a_result_and_skips_at_other_caps_stay_apart():
    done = _read([(KEY + "2000000", {"gaps": {"paper": 0.01}, "optimum": 2.0, "states": 9}),
                  (KEY + "2000000", {"skipped": "took too long"}),
                  (KEY + "3000000", {"skipped": "too many states"})])
    assert done[KEY + "2000000"]["gaps"] == {"paper": 0.01}
    assert done[KEY + "3000000"] == {"skipped": "too many states"}


def test_a_later_rerun_of_one_policy_keeps_the_others_gaps():
    done = _read([(KEY + "2000000", {"gaps": {"paper": 0.01, "lookahead": 0.01}, "optimum": 2.0, "states": 9}),
                  (KEY + "2000000", {"gaps": {"lookahead": 0.0}, "optimum": 2.0, "states": 9})])
    assert done[KEY + "2000000"]["gaps"] == {"paper": 0.01, "lookahead": 0.0}
