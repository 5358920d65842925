"""The count-based rules decide as they did before the answering layer (policies/answers.py) took
over their budget machinery: every decision of a fixed set of seeded assemblies, replayed.

The fixture ``tests/data/decisions_recorded.json.gz`` (gzip-compressed JSON) was made by running this file as a script
(``python tests/test_decisions_recorded.py``) on the code before the rules were rewritten over
the answering layer (commit e1c5243): for each case (a plan, a policy, a bin size, a buffer
capacity, a seed) it holds every decision's ``to_dict()`` and ``explain()`` along one simulated
assembly.  The looks come from a seeded stream of their own (:func:`play`), so the assembly
depends only on the decisions.  The policies are exact (no budget), or budgeted with a budget
so large that every count fits (the budgeted path's exact branch: its order of attempts, its
moving averages and its deadlines, with the same answers).  The look-ahead decides on the
optimum's programme for the small plans and on its base (slack) for KILBRID.  Recorded again when the
uniform bin's optimum came to sum its looks as order statistics: every action the same, the optimum's
printed expectations within 1e-4 (their last digit's rounding), and KILBRID's reason for deciding by
the base in the words of states and bytes.  The look-ahead's KILBRID case recorded again when its fallback
in the uniform bin became the frontier window's optimum (policies/window.py) instead of slack, and when the
optimum's state cap rose to 32,000,000 (every action the same; only the cap's figure in its reason), and when
the window on plans of one strategy came to take the parts that unlock the most first and to install the ready
parts outside it (its decisions changed by design: docs/decisions.md measures them against the optimum), and
when its windows before a run's first installation came to hold more states (every action the same; the
first two decisions' notes name the larger window), and when its programme came to count the parts
interchangeable at a state as one part's units and the window stopped passing over an installation (or,
with an unlimited buffer, over a part seen) as the optimum never does (its decisions changed by design from
the 41st; the assembly took 62 decisions instead of 64).
"""

from __future__ import annotations

import gzip
import json
import random
import sys
from pathlib import Path

import pytest

FIXTURE = Path(__file__).parent / "data" / "decisions_recorded.json.gz"
ROOT = Path(__file__).parent.parent
BIG_BUDGET = 60.0   # seconds per decision: every count of these plans fits (the exact branch of a budgeted rule)


def random_plan(seed: int, n: int, density: float, strategies: int = 1):
    """A plan of ``n`` parts (some of quantity 2) with ``strategies`` random orders of that density."""
    from opportune import make_plan

    rng = random.Random(seed)
    ids = [f"p{i}" for i in range(n)]
    parts = [{"id": p, "quantity": 2} if rng.random() < 0.2 else p for p in ids]
    orders = []
    for _ in range(strategies):
        perm = rng.sample(ids, n)
        req: dict[str, list[str]] = {}
        for j in range(n):
            for i in range(j):
                if rng.random() < density:
                    req.setdefault(perm[j], []).append(perm[i])
        orders.append(req)
    if strategies == 1:
        return make_plan(parts, orders[0], name=f"random-{seed}")
    from opportune.formats import plan_from_dict

    return plan_from_dict({"name": f"random-{seed}", "parts": parts,
                           "strategies": [{"name": f"s{k}", "requires": r} for k, r in enumerate(orders)]})


def plan_of(name: str):
    from opportune.formats.loader import load_plan

    if name == "gearbox":
        return load_plan(str(ROOT / "examples" / "gearbox.yaml"))
    if name.startswith("salbp:"):
        return load_plan(name)
    _, seed, n, density, k = name.split(":")
    return random_plan(int(seed), int(n), float(density), int(k))


def policy_of(name: str, visible: int, capacity: int | None):
    from opportune.policies.named import make_policy

    policy, _, budget = name.partition("@")
    return make_policy(policy, budget=float(budget) if budget else None, visible=visible, capacity=capacity)


#: (plan, policy[@budget], parts per look, buffer capacity, seed)
CASES = [
    (plan, policy, visible, capacity, seed)
    for plan in ("gearbox", "random:1:9:0.25:1", "random:2:8:0.3:2", "random:3:8:0.2:3")
    for policy in ("paper", "bin-first", "slack", "lookahead", f"paper@{BIG_BUDGET:g}", f"slack@{BIG_BUDGET:g}")
    for visible, capacity, seed in ((3, 2, 1), (2, None, 2))
] + [("salbp:KILBRID", policy, 3, None, 5)
     for policy in ("paper", "bin-first", "slack", "lookahead", f"paper@{BIG_BUDGET:g}", f"bin-first@{BIG_BUDGET:g}",
                    f"slack@{BIG_BUDGET:g}")]


def play(plan_name: str, policy_name: str, visible: int, capacity: int | None, seed: int) -> list[dict]:
    """Every decision of one assembly: the looks are drawn from ``random.Random(seed)`` over the units
    still in the bin (up to ``visible`` of them, in declaration order); a shake draws a new look."""
    from opportune.engine import OrderEngine
    from opportune.sequencer import Sequencer

    plan = plan_of(plan_name)
    engine = OrderEngine(plan)
    policy = policy_of(policy_name, visible, capacity)
    seq = Sequencer(engine, policy, buffer_capacity=capacity)
    rng = random.Random(seed)
    index = {p: i for i, p in enumerate(plan.part_ids)}
    in_bin = [p.id for p in plan.parts for _ in range(p.quantity)]
    out = []
    while not seq.state.is_complete and len(out) < 400:
        look = tuple(sorted(rng.sample(in_bin, min(visible, len(in_bin))), key=index.__getitem__))
        d = seq.decide(look)
        out.append({"look": list(look), "decision": d.to_dict(), "explain": d.explain()})
        a = d.action
        if a.kind in ("install", "buffer") and a.source != "buffer":
            in_bin.remove(a.part)
        seq.report("success")
    return out


def case_id(case) -> str:
    return "-".join(str(x) for x in case)


@pytest.fixture(scope="module")
def recorded() -> dict:
    return json.loads(gzip.decompress(FIXTURE.read_bytes()))


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_the_rules_decide_as_recorded(case, recorded):
    """Each decision of the assembly, its explanation and its dict, equal to the recorded one (the
    first difference is reported with its look)."""
    want = recorded[case_id(case)]
    got = play(*case)
    for i, (g, w) in enumerate(zip(got, want)):
        assert g == w, f"decision {i} of {case_id(case)} differs"
    assert len(got) == len(want)
    assert all(d["decision"]["exact"] for d in got)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "src"))
    FIXTURE.parent.mkdir(exist_ok=True)
    text = json.dumps({case_id(c): play(*c) for c in CASES}, indent=None, separators=(",", ":")) + "\n"
    FIXTURE.write_bytes(gzip.compress(text.encode(), compresslevel=9, mtime=0))
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size:,} bytes)")
