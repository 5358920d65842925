"""CPU seconds of the exact evaluation of the default policy without its optimum (the lab's ``fallback``
column), asking the policy for all the looks of a state at once (``PolicyEvaluator.LOOKS_AT_ONCE``, the
default) against look by look (as before), on the lab's plans.  The two runs of a plan-setting alternate
in one process, so that the machine's load weighs on both alike; the values must agree to the bit.

    python benchmarks/bench_evaluate_looks.py --cases r1-16:1:2,r1-16:2:1,r0-16:3:1 --repeats 2
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

from opportune.engine import OrderEngine
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead

sys.path.insert(0, str(Path(__file__).resolve().parent))
from policy_lab import generate  # noqa: E402  (the lab's plans, by name)


def one(plan, visible: int, capacity: int | None, at_once: bool) -> tuple[float, float, int, int]:
    """The fallback's value, the CPU seconds it took, its states and the windows solved."""
    engine = OrderEngine(plan)
    policy = Lookahead(optimal=False, visible=visible, capacity=capacity)
    ev = PolicyEvaluator(engine, policy, visible=visible, capacity=capacity, max_states=2_000_000)
    ev.LOOKS_AT_ONCE = at_once
    cpu = time.process_time()
    value = ev.value()
    return value, time.process_time() - cpu, ev.policy_states, policy.window.work["windows"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="r1-16:1:2,r1-16:2:1,r0-16:3:1",
                    help="plan:visible:capacity, comma-separated (the lab's seed-0 plans; capacity inf: unlimited)")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    print(f"load {os.getloadavg()[0]:.1f} (1 min) on {os.cpu_count()} cores")
    print("| plan | visible | buffer | states | windows | look by look (s CPU) | all looks at once (s CPU) | ratio |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for case in args.cases.split(","):
        name, visible, capacity = case.split(":")
        size = int(name.split("-")[1].split("x")[0])
        plan = {p.name: p for p, _ in generate(0, 30, size, size)}[name]
        cap = None if capacity == "inf" else int(capacity)
        before, after = [], []
        for _ in range(args.repeats):
            v0, t0, states, windows = one(plan, int(visible), cap, False)
            v1, t1, _, _ = one(plan, int(visible), cap, True)
            assert v0 == v1, (v0, v1)
            before.append(t0)
            after.append(t1)
        b, a = statistics.median(before), statistics.median(after)
        print(f"| {name} | {visible} | {capacity} | {states:,} | {windows:,} | {b:.2f} | {a:.2f} | {b / a:.2f} |")
    print(f"load {os.getloadavg()[0]:.1f} (1 min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
