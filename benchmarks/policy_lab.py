"""The policy lab: every policy evaluated exactly against the optimum, in every setting, on random plans
of the sizes users have, the SALBP graphs, the gearbox and any folder of plans.

Plans.  ``--sizes`` names groups of ``--plans`` random plans each (a third with two strategies; seeded
by ``--seed`` alone, so a group's plans do not depend on the others): ``8-12`` is the small lab (parts
drawn from 8 to 12, edge probability 0.1, 0.2 or 0.3: :data:`DENSITIES`), and 16, 20, 25 and 30 are
the sizes users have (edge probability 0.2-0.35: :data:`USER_DENSITIES`; sparser plans of these sizes
have optima far over any state cap).  Then ``--salbp`` (KILBRID, TONGE70, ARC111), every plan file in
``--plans-dir`` and the gearbox.

Settings.  ``--visible`` (1, 2, 3) × ``--capacities`` (1, 2, 3, unlimited) × ``--bins`` (uniform,
pile).  Each policy's exact expected time (:class:`~opportune.policies.evaluate.PolicyEvaluator` in
the uniform bin, :class:`~opportune.policies.pile.PileSolver` in the pile) is divided by the optimum's
(the compiled programme where the core is built; ``--python-optimum``: the Python one, the same values).
The optimum's states are counted before the work (:func:`~opportune.policies.states.estimate_states`, on
the plan the programme stores: interchangeable parts merged in the uniform bin's compiled optimum):
a plan-setting whose optimum needs more than ``--max-states`` is skipped with that count, one whose
optimum is cut during the work by its states or ``--task-seconds`` likewise, with how far it got (the
states stored, CPU seconds, peak memory: the wall), and a policy whose evaluation takes over
``--task-seconds`` or stores over ``--policy-states`` states (counted work: the same cut on a loaded
machine as on an idle one) is left out of that column (said, never hidden).  Where the look-ahead decides by the
optimum (its decisions say so), its value is the optimum's, as in ``opportune evaluate``.  No Monte
Carlo: every number is exact, except where ``--estimate-runs`` is given: there a policy whose exact evaluation
would take too long (the optimum over ``--estimate-above`` states) has its gap estimated from seeded runs by
its regrets over the optimum (unbiased, with its standard error; listed as such in the tables).

Columns.  ``lookahead`` is the default policy; ``fallback`` the default with its exact optimum switched
off (``Lookahead(optimal=False)``, ``evaluate --without-optimum``; asked for with ``--without-optimum``):
what decides where the optimum's programme does not fit; ``paper`` the paper's rule.  The tables
(``--table``, ``--readme``, ``--plot``) are written from ``--results`` alone, per size and setting, each
plan-setting at the largest state cap it was attempted with (an optimum found at any cap wins).

Results.  ``--results`` gets one JSON line per plan-setting as it finishes (an interrupted run goes on
where it stopped); a later line adds its policies' gaps to an earlier one's, and only the policies a
plan-setting lacks are run.  Each gap carries its policy's version (:data:`POLICY_VERSIONS`, and
:data:`BIN_VERSIONS` where a bin's decisions changed alone): when a policy's decisions change (a new
fallback), bump its version and rerun that column alone; its old gaps are then stale and dropped from the
tables::

    python benchmarks/policy_lab.py --results benchmarks/policy_lab_results.jsonl --policies fallback \\
        --table docs/policy-lab.md --readme README.md --plot docs/img/policy-lab.png --paired "" --workers 2

The whole lab (hours; resumable), and the order it was run in (the cheap columns first)::

    python benchmarks/policy_lab.py --results benchmarks/policy_lab_results.jsonl --without-optimum \\
        --table docs/policy-lab.md --readme README.md --plot docs/img/policy-lab.png --paired "" --workers 2
    python benchmarks/policy_lab.py --results R --policies lookahead --capacities 1,2 --paired "" --task-seconds 60
    python benchmarks/policy_lab.py --results R --policies lookahead --capacities 3,inf --paired "" --task-seconds 60
    python benchmarks/policy_lab.py --results R --policies paper --capacities 1,2 --salbp "" --paired "" \
        --task-seconds 120 --only r0-16,r1-16,r2-16x2,...      # the first plans of each size first
    python benchmarks/policy_lab.py --results R --policies fallback --paired "" --only ...
    python benchmarks/policy_lab.py --results R --policies fallback --sizes 16,20,25,30 --plans 6 --salbp "" \
        --paired "" --only r0-16,r1-16,r3-16,... --policy-states 12000 --cheapest-first   # a counted cut
    python benchmarks/policy_lab.py --results R --policies fallback --bins pile --sizes 25 --visible 3 \
        --capacities 1 --salbp "" --paired "" --estimate-runs 1000 --estimate-above 1000000   # estimated gaps
    python benchmarks/policy_lab.py --results R --no-run --table docs/policy-lab.md --readme README.md \\
        --plot docs/img/policy-lab.png --paired ""                                   # the tables alone

Others::

    python benchmarks/policy_lab.py --sizes 8-12 --plans 10 --visible 2 --capacities inf --bins uniform
    python benchmarks/policy_lab.py --sizes 16 --plans 6 --visible 1 --capacities 1 --bins uniform \\
        --policies lookahead --without-optimum --paired ""      # the fallback beside the optimum
    python benchmarks/policy_lab.py --plans 0 --salbp "" --plans-dir my-plans/ --paired ""
    python benchmarks/policy_lab.py --plans 0 --salbp "" --paired salbp:KILBRID --paired-trials 400
    python benchmarks/policy_lab.py --plans 0 --salbp "" --paired salbp:KILBRID --bound   # a lower bound beside

Plans too large for exact evaluation (``--paired``, default KILBRID and TONGE70) are compared by paired
Monte Carlo instead: every policy runs on the same ``--paired-trials`` random bins (trial ``i`` of each
sees the same bin), and the table gives each policy's mean time and its mean difference from the
paper's rule with the 95% interval of that difference (Student's t).
"""

from __future__ import annotations

import argparse
import json
import random
import re
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from opportune import load_plan, make_plan
from opportune.engine import OrderEngine
from opportune.engine.deadline import Deadline
from opportune.planning.costs import TimeModel
from opportune.policies.evaluate import PolicyEvaluator
from opportune.policies.lookahead import Lookahead
from opportune.policies.opportunistic import Opportunistic
from opportune.policies.optimal import (
    OptimalSolver,
    OptimalTooLarge,
    OutOfTime,
    optimal_solver,
    optimum_engine,
)
from opportune.policies.pile import PileSolver, pile_solver
from opportune.policies.regret import estimate_gap
from opportune.policies.states import big, estimate_states
from opportune.policies.variants import BinFirst, Slack

HERE = Path(__file__).resolve().parent
GEARBOX = HERE.parent / "examples" / "gearbox.yaml"

#: Edge probabilities of the small lab's plans (8-12 parts).
DENSITIES = (0.1, 0.2, 0.3)
#: Edge probabilities of plans of more than 12 parts: at 25-30 parts a plan of 0.1 needs 10^6-10^8
#: states in every setting (over any cap), one of 0.2-0.35 10^3-10^6 with 1-3 locations.
USER_DENSITIES = (0.2, 0.25, 0.3, 0.35)
#: Seconds for counting the optimum's states before the work (past it, the down-set estimate).
ESTIMATE_SECONDS = 5.0
#: The seed of the runs that estimate a policy's gap (``--estimate-runs``): every row's the same.
ESTIMATE_SEED = 0
#: The version of what each policy decides, stored with its gaps: bump one when its decisions change and
#: rerun ``--policies NAME``; gaps measured at another version are stale (dropped from the tables).
#: Uniform bin: with one strategy open, windows of 16 and 20 parts tried while predicted to fit; with several,
#: the option's value of a state where every unit left is buffered takes its look (as the optimum's).  Then
#: ten times the states a window before a run's first installation (as the pile's).  Then the parts
#: interchangeable at the state merged in a window's programme, and no shake or buffering that passes over an
#: installation (or, with an unlimited buffer, over a part seen) as the optimum never does.
POLICY_VERSIONS = {"fallback": "one strategy: windows up to 20 parts; the all-buffered look; ten times the states "
                               "before a run's first installation; interchangeable parts merged, no installation "
                               "passed over"}
#: Versions of a policy in one bin where it differs from :data:`POLICY_VERSIONS` there: the pile's fallback
#: became the pile's own frontier window (``policies/pile_window.py``) while the uniform bin's decisions
#: stayed, so pile rows measured before (tagged "frontier window", the step over slack in fact) are stale;
#: then its state cap went from 20,000 to 30,000 (the compiled core made it affordable); then a window per
#: open strategy, each look taking the least of their moves with the option value of keeping several open;
#: then a move keeping several open valued a look deeper, by the windows of the state it leads to.
#: Then, with several strategies open and 2 visible or 2 locations, the look's parts near each strategy's
#: frontier taken first.  Then, with several strategies open and 2 locations or more, three times the states
#: a window (one strategy, or one location: the same decisions).  Then sizes up to 20 parts (up to 12 with
#: several strategies open and one location), and a window predicted to fit that does not raises the
#: prediction for a smaller one (every setting).  Then ten times the states before a run's first installation.
#: Then, with two locations or more and no deadline, three times the states a window (one location as before).
#: Then, with one location and several strategies open, a move keeping them open valued by the one-look option
#: value (as with two locations or more), not a look deeper, and so windows up to 20 parts there too.  Then
#: three times the states a window with one location too (no deadline).  Then, with one location, the start's
#: ten times the states until three units are installed (no deadline).
_PILE_BEFORE_LOCATIONS = ("pile window, sizes up to 20 parts (12 at 1 location with several open), "
                          "a missed prediction retried smaller, ten times the states before a run's first installation")
_PILE_BEFORE_ONE_LOOK = _PILE_BEFORE_LOCATIONS + "; three times the states with two locations or more"
_PILE_BEFORE_ONE_LOCATION = _PILE_BEFORE_ONE_LOOK + "; the one-look option value at one location"
_PILE_BEFORE_EARLY = _PILE_BEFORE_ONE_LOCATION + "; three times the states with one location too"
BIN_VERSIONS = {("fallback", "pile"): _PILE_BEFORE_EARLY + "; at one location the start's cap until three units are installed"}
#: The version a results line without one measured (lines written before versions were stored).
UNTAGGED = {"fallback": "step over slack"}
#: Earlier versions whose decisions on plans of one strategy are the current version's (a change that
#: touches only plans of several strategies): their gaps on one-strategy plans are current.
SAME_ON_ONE_STRATEGY = {"fallback": ()}     # the current version changed the decisions on one strategy
#: As :data:`SAME_ON_ONE_STRATEGY`, in a bin with a version of its own.
BIN_SAME_ON_ONE_STRATEGY = {("fallback", "pile"): ()}     # the current version changed those too
#: Earlier versions whose decisions on plans of several strategies are the current version's (a change that
#: touches only plans of one strategy), in a bin without a version of its own.
SAME_ON_SEVERAL_STRATEGIES = {"fallback": ()}     # the current version changed those too
#: Earlier versions whose decisions in these settings ((visible, capacity)) are the current version's, by bin:
#: with two locations or more (or unlimited) the look deeper never applied, the locations' factor already did,
#: and the start's cap holds before the first installation only.
BIN_SAME_AT: dict = {("fallback", "pile"): {(visible, capacity): (_PILE_BEFORE_EARLY, _PILE_BEFORE_ONE_LOCATION,
                                                                  _PILE_BEFORE_ONE_LOOK)
                                            for visible in (1, 2, 3) for capacity in (2, 3, None)}}
#: As :data:`BIN_SAME_AT`, on plans of one strategy only (a change of the several-strategy valuation at one
#: location leaves them); the locations' factor at one location touched them too: none.
BIN_SAME_AT_ON_ONE_STRATEGY: dict = {("fallback", "pile"): {}}


def policy_version(name: str, bin: str) -> str | None:
    """The version of ``name``'s decisions in ``bin`` (None: not versioned)."""
    return BIN_VERSIONS.get((name, bin), POLICY_VERSIONS.get(name))


def policies(visible: int, capacity: int | None, bin: str = "uniform"):
    """The lab's policies by name; ``fallback`` is the default (lookahead) with its exact optimum switched
    off (``--without-optimum``): what decides where the optimum's programme does not fit."""
    return {"paper": Opportunistic(), "bin-first": BinFirst(), "slack": Slack(),
            "lookahead": Lookahead(visible=visible, capacity=capacity, bin=bin),
            "fallback": Lookahead(visible=visible, capacity=capacity, bin=bin, optimal=False)}


def random_plan(rng: random.Random, n: int, strategies: int, density: float, label: str = "random"):
    ids = [f"p{i}" for i in range(n)]

    def requires() -> dict[str, list[str]]:
        order = ids[:]
        rng.shuffle(order)
        out: dict[str, list[str]] = {}
        for j, b in enumerate(order):
            before = [a for a in order[:j] if rng.random() < density]
            if before:
                out[b] = before
        return out

    if strategies == 1:
        return make_plan(ids, requires(), name=f"{label}-{n}")
    return make_plan(ids, strategies={f"s{k}": requires() for k in range(strategies)}, name=f"{label}-{n}x{strategies}")


# ------------------------------------------------------------------ one plan in one setting


def _optimum(engine, bin: str, settings: dict, python: bool) -> OptimalSolver:
    if bin == "pile":
        return (PileSolver if python else pile_solver)(engine, **settings)
    return OptimalSolver(engine, **settings) if python else optimal_solver(engine, **settings)


def _wall(optimum, cpu: float) -> dict:
    """What the optimum's programme (or a policy's evaluation) reached where it was cut (by its state cap or
    its time): the states it stored (those whose value it finished), the CPU seconds it took, the process's
    peak resident memory in MB (a worker's peak since it started: this plan-setting's where it ran alone)
    and the bytes the compiled programme held (None: the Python programme's are not measured)."""
    try:
        import resource         # Unix only
        rss_mb = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)     # kilobytes on Linux
    except ImportError:
        rss_mb = None
    states = getattr(optimum, "policy_states", optimum.states)     # a policy's evaluation: the policy's own
    return {"states": states, "cpu": round(cpu, 1), "rss_mb": rss_mb, "bytes": getattr(optimum, "bytes", None)}


def _decides_by_pile_optimum(engine, policy, visible: int, deadline) -> bool:
    """Whether the look-ahead decides by the pile's optimum on this plan: its first decision prepares its
    programme and says which rule decided (the uniform bin's evaluator asks ``decides_by_optimum``)."""
    if not isinstance(policy, Lookahead):
        return False
    policy.deadline = deadline
    look = tuple(p.id for p in engine.plan.parts)[:visible]
    policy.choose_at(engine, 0, engine.all_strategies, (), float("inf"), look)
    return policy.deciding_rule == Lookahead.OPTIMAL_RULE


def _by_optimum(engine, policy, bin: str, settings: dict, deadline) -> bool:
    """Whether the policy decides by the optimum on this plan and setting (then its value is the optimum's)."""
    if bin == "pile":
        return _decides_by_pile_optimum(engine, policy, settings["visible"], deadline)
    # as PolicyEvaluator.takes_optimum, without solving the optimum a second time
    decides = getattr(policy, "decides_by_optimum", None)
    return decides is not None and decides(engine, settings["visible"], settings["capacity"], TimeModel())


def _policy_value(engine, policy, bin: str, settings: dict, seconds: float | None, best: float,
                  held: list | None = None) -> tuple[float, bool]:
    """A policy's exact expected time, and whether it is the optimum's (the policy decides by it); its
    evaluation's programme is put in ``held`` (to tell how far it got where it is cut)."""
    deadline = Deadline.after(seconds)
    if _by_optimum(engine, policy, bin, settings, deadline):
        return best, True
    ev = (PileSolver if bin == "pile" else PolicyEvaluator)(engine, policy, **settings)
    ev.deadline = deadline
    if held is not None:
        held.append(ev)
    value = ev.value()
    return value, bool(getattr(ev, "by_optimum", False))


def _policy_estimate(engine, policy, bin: str, settings: dict, seconds: float | None, optimum,
                     runs: int) -> dict | None:
    """A policy's gap estimated from ``runs`` seeded runs by its regrets over the optimum
    (:func:`~opportune.policies.regret.estimate_gap`: unbiased, its standard error given), in place of its exact
    evaluation; None where it decides by the optimum (its gap 0, exactly)."""
    deadline = Deadline.after(seconds)
    if _by_optimum(engine, policy, bin, settings, deadline):
        return None
    est = estimate_gap(optimum, policy, runs=runs, seed=ESTIMATE_SEED, pile=bin == "pile", deadline=deadline)
    return {"gap": est.gap, "se": est.se, "runs": est.runs, "seed": est.seed, "looks": est.looks,
            "differing": est.differing, "cost_gap": est.cost / est.optimum - 1, "cost_se": est.cost_se / est.optimum}


def measure(plan, visible: int, capacity: int | None, bin: str = "uniform", *, max_states: int = 2_000_000,
            seconds: float | None = None, only=None, python: bool = False, policy_states: int | None = None,
            estimate: tuple[int, int] | None = None) -> dict:
    """One plan in one setting: the optimum, its states and each policy's gap over it (with the CPU seconds
    each took, the versions, the policies out of time or states and those worth the optimum); or
    ``{"skipped": why, "estimate": states, "low": proven}`` where the optimum does not fit (counted first), with
    ``"measured"`` (:func:`_wall`) where it was cut during the work by its states or time; a policy cut so
    has its ``"policy_measured"``.
    ``policy_states``: the states a policy's evaluation may store (counted work, the same cut on a loaded
    machine as on an idle one; None: ``max_states``).  ``estimate``: ``(runs, states)``: where the optimum
    has more than ``states`` states, a policy's gap is estimated from ``runs`` seeded runs
    (:func:`_policy_estimate`) instead of evaluated exactly, and recorded under ``"estimated"`` too."""
    engine = OrderEngine(plan)
    # counted on the plan the programme stores: the uniform bin's compiled optimum merges interchangeable
    # parts (KILBRID with 2 locations: 27.5 million states merged against about 163 million as declared)
    sized = engine if bin == "pile" or python else optimum_engine(engine)
    est = estimate_states(sized, visible=visible, capacity=capacity, pile=bin == "pile", stop_above=max_states,
                          time_limit=ESTIMATE_SECONDS)
    if est.over(max_states):
        return {"skipped": f"optimum over {max_states:,} states: {est.describe()}", "estimate": est.states,
                "low": est.low}
    settings = dict(visible=visible, capacity=capacity, max_states=max_states)
    cpu = time.process_time()
    optimum = _optimum(engine, bin, settings, python)
    optimum.deadline = Deadline.after(seconds)
    try:
        best = optimum.value()
    except (OptimalTooLarge, OutOfTime) as exc:
        cut = f"{max_states:,} states" if isinstance(exc, OptimalTooLarge) else f"{seconds:g} s"
        return {"skipped": f"optimum over {cut}", "estimate": est.states, "low": est.low,
                "measured": _wall(optimum, time.process_time() - cpu)}
    settings["max_states"] = policy_states or max_states
    out = {"optimum": best, "states": optimum.states, "gaps": {}, "policy_skipped": {}, "by_optimum": [],
           "cpu": {"optimum": round(time.process_time() - cpu, 3)}, "versions": {}}
    for name, policy in policies(visible, capacity, bin).items():
        if only is not None and name not in only:
            continue
        cpu, held = time.process_time(), []
        try:
            if estimate is not None and optimum.states > estimate[1]:
                est = _policy_estimate(engine, policy, bin, settings, seconds, optimum, estimate[0])
                by_optimum = est is None
                out["gaps"][name] = 0.0 if by_optimum else est["gap"]
                if est is not None:
                    out.setdefault("estimated", {})[name] = est
            else:
                value, by_optimum = _policy_value(engine, policy, bin, settings, seconds, best, held)
                out["gaps"][name] = value / best - 1
            if by_optimum:
                out["by_optimum"].append(name)
            elif name == "lookahead" and policy.refusal:     # the default did not decide by its optimum: why
                out["refusals"] = {name: policy.refusal}
        except OptimalTooLarge:
            out["policy_skipped"][name] = f"over {settings['max_states']:,} states"
        except OutOfTime:
            out["policy_skipped"][name] = f"over {seconds:g} s"
        if name in out["policy_skipped"] and held:      # how far its evaluation got
            out.setdefault("policy_measured", {})[name] = _wall(held[0], time.process_time() - cpu)
        if name == "lookahead" and name in out["policy_skipped"] and policy.refusal:
            out["policy_skipped"][name] += f"; it did not decide by its optimum: {policy.refusal}"
        out["cpu"][name] = round(time.process_time() - cpu, 3)
        if policy_version(name, bin) is not None:
            out["versions"][name] = policy_version(name, bin)
    return out


def gaps(plan, visible: int, capacity: int | None, bin: str = "uniform", *, max_states: int = 2_000_000,
         seconds: float | None = None, only=None, compiled: bool = True) -> tuple[dict[str, float], float, int]:
    """Each policy's exact expected time over the optimum's, less one; the optimum; its states (see
    :func:`measure`).  Raises OptimalTooLarge past ``max_states`` states and OutOfTime past ``seconds``
    (the optimum, or one policy)."""
    r = measure(plan, visible, capacity, bin, max_states=max_states, seconds=seconds, only=only, python=not compiled)
    if "skipped" in r:
        raise (OutOfTime if r["skipped"].endswith(" s") else OptimalTooLarge)(r["skipped"])
    for why in r["policy_skipped"].values():
        raise (OutOfTime if why.endswith(" s") else OptimalTooLarge)(why)
    return r["gaps"], r["optimum"], r["states"]


def _task(job):
    """One plan in one setting (a worker's job): :func:`measure`'s record."""
    plan, visible, capacity, bin, max_states, seconds, only, python, policy_states, estimate = job
    return measure(plan, visible, capacity, bin, max_states=max_states, seconds=seconds, only=only, python=python,
                   policy_states=policy_states, estimate=estimate)


# ------------------------------------------------------------------ the jobs and the results file


@dataclass(frozen=True)
class Job:
    """One plan in one setting: its key in ``--results``, its group (a size, ``SALBP``, a folder), the
    plan, the setting (visible, capacity, bin) and whether the plan has two strategies."""
    key: str
    group: str
    plan: object
    setting: tuple
    two: bool


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """``"8-12,16"`` → ``[(8, 12), (16, 16)]``."""
    out = []
    for part in filter(None, text.split(",")):
        lo, _, hi = part.partition("-")
        out.append((int(lo), int(hi or lo)))
    return out


def size_label(lo: int, hi: int) -> str:
    return f"{lo}–{hi}" if lo != hi else str(lo)


def generate(seed: int, count: int, lo: int, hi: int) -> list[tuple[object, bool]]:
    """``count`` random plans of ``lo`` to ``hi`` parts, each with whether it has two strategies (every
    third); the group's own stream from ``seed`` (the small lab's plans as they always were)."""
    rng = random.Random(seed)
    out = []
    for i in range(count):
        n = rng.randint(lo, hi)
        k = 2 if i % 3 == 2 else 1
        density = rng.choice(DENSITIES if hi <= 12 else USER_DENSITIES)
        out.append((random_plan(rng, n, k, density, label=f"r{i}"), k == 2))
    return out


def _key(seed: int, group: str, plan, setting, max_states: int) -> str:
    """A job's identity in ``--results``: the plans' generator (seed and sizes), the plan, the setting, the cap."""
    visible, capacity, bin = setting
    return f"{seed}:{group}:{plan.name}:{visible}:{'inf' if capacity is None else capacity}:{bin}:{max_states}"


def _fresh(rec: dict) -> dict:
    """``rec`` without the gaps measured, and the policies skipped, at another version of their policy
    (:data:`POLICY_VERSIONS`)."""
    if "gaps" not in rec:
        return rec
    versions = {**UNTAGGED, **rec.get("versions", {})}

    def current(n: str) -> bool:
        v, bin = versions.get(n), rec.get("bin", "uniform")
        if v == policy_version(n, bin):
            return True
        setting = (rec.get("visible"), rec.get("capacity"))
        if v in BIN_SAME_AT.get((n, bin), {}).get(setting, ()):
            return True         # a change that touched other settings only
        if not rec.get("two_strategies") and v in BIN_SAME_AT_ON_ONE_STRATEGY.get((n, bin), {}).get(setting, ()):
            return True         # a change that touched other settings' plans of one strategy only
        own = (n, bin) in BIN_VERSIONS
        if rec.get("two_strategies"):   # a change that touched only plans of one strategy
            return not own and v in SAME_ON_SEVERAL_STRATEGIES.get(n, ())
        # a change that touched only plans of several strategies
        return v in (BIN_SAME_ON_ONE_STRATEGY.get((n, bin), ()) if own else SAME_ON_ONE_STRATEGY.get(n, ()))

    gaps = {n: g for n, g in rec["gaps"].items() if current(n)}
    # a policy skipped (out of time, or past a counted cut) at another version is to be run again, as a gap is
    skipped = {n: w for n, w in rec.get("policy_skipped", {}).items() if current(n)}
    estimated = {n: e for n, e in rec.get("estimated", {}).items() if n in gaps}
    return {**rec, "gaps": gaps, **({"policy_skipped": skipped} if "policy_skipped" in rec else {}),
            **({"estimated": estimated} if "estimated" in rec else {})}


def _keep(done: dict, key: str, rec: dict, max_states: int) -> None:
    """Read one line of ``--results`` into ``done``. An exact result stands whatever state cap it was
    run with (the cap decides only whether a plan is skipped), so it is filed under this run's cap; a
    later line wins, its gaps added to an earlier result's (a rerun of one policy keeps the others'),
    a policy's gap is never hidden by a later skip of it, and a skip never hides a result."""
    rec = _fresh(rec)
    if "skipped" not in rec:
        key = f"{key.rsplit(':', 1)[0]}:{max_states}"
    old = done.get(key)
    if "skipped" in rec:
        if old is None or "skipped" in old:
            done[key] = rec
        return
    if old is not None and "skipped" not in old:
        gaps = {**old["gaps"], **rec["gaps"]}
        skipped = {n: w for n, w in {**old.get("policy_skipped", {}), **rec.get("policy_skipped", {})}.items()
                   if n not in gaps}
        refusals = {**{n: w for n, w in old.get("refusals", {}).items() if n not in rec["gaps"]}, **rec.get("refusals", {})}
        # a gap measured again replaces the earlier one's estimate (exact now, or estimated again)
        estimated = {**{n: e for n, e in old.get("estimated", {}).items() if n not in rec["gaps"]},
                     **rec.get("estimated", {})}
        rec = {**old, **rec, "gaps": gaps, "policy_skipped": skipped, "refusals": refusals, "estimated": estimated,
               "by_optimum": sorted(set(old.get("by_optimum", [])) | set(rec.get("by_optimum", []))),
               "cpu": {**old.get("cpu", {}), **rec.get("cpu", {})},
               "versions": {**old.get("versions", {}), **rec.get("versions", {})}}
    done[key] = rec


def read_results(path: Path | None, max_states: int) -> dict[str, dict]:
    """Every plan-setting of a results file by key (see :func:`_keep`)."""
    done: dict[str, dict] = {}
    if path is not None and path.exists():
        # a line not yet ended by its newline is being written by a run going on: not read
        for line in path.read_text().split("\n")[:-1]:
            if line.strip():
                rec = json.loads(line)
                _keep(done, rec.pop("key"), rec, max_states)
    return done


def _record(job: Job, r: dict) -> dict:
    visible, capacity, bin = job.setting
    return {"plan": job.plan.name, "visible": visible, "capacity": capacity, "bin": bin, "two_strategies": job.two,
            **{k: v for k, v in r.items() if v or k == "gaps"}}


def _missing(rec: dict | None, asked, redo_skipped: bool) -> tuple[str, ...]:
    """The asked policies a plan-setting still needs (all where it was not run, or skipped and redone)."""
    if rec is None or "skipped" in rec:
        return tuple(asked) if rec is None or redo_skipped else ()
    tried = set(rec["gaps"]) | (set() if redo_skipped else set(rec.get("policy_skipped", {})))
    return tuple(p for p in asked if p not in tried)


def wall_words(measured: dict) -> str:
    """What a cut programme reached (:func:`_wall`), in words: ``'2,000,001 states finished in 41.3 CPU s,
    the process's peak memory 230 MB (the programme's table 96 MB)'`` (a state is stored once its value is known: a
    programme that descends far before the first finishes may be cut with none)."""
    out = f"{measured['states']:,} states finished in {measured['cpu']:,} CPU s"
    if measured.get("rss_mb") is not None:
        out += f", the process's peak memory {measured['rss_mb']:,} MB"
    if measured.get("bytes") is not None:
        out += f" (the programme's table {measured['bytes'] / 2 ** 20:,.0f} MB)"
    return out


def describe(setting, r: dict, name: str) -> str:
    if "skipped" in r:
        wall = f"; {wall_words(r['measured'])}" if "measured" in r else ""
        return f"{setting_name(*setting)}: {name}: skipped ({r['skipped']}{wall})"
    measured = [f"{p} {100 * v:+.3f}%" for p, v in r["gaps"].items()]
    left = [f"{p} {why}" for p, why in r.get("policy_skipped", {}).items()]
    return (f"{setting_name(*setting)}: {name}: optimum {r['optimum']:.4f} ({r['states']:,} states); "
            + ", ".join(measured + left))


def _run_jobs(jobs: list[Job], args, done: dict, sink) -> None:
    """Run what the jobs lack of the asked policies, each reported as it finishes (a full run takes hours)
    and appended to ``--results`` at once, so that an interrupted run goes on from where it stopped."""
    todo = [(job, need) for job in jobs if (need := _missing(done.get(job.key), args.policies, args.redo_skipped))]
    if args.cheapest_first:     # by the optimum's states --results has for them (those without last), stably
        todo.sort(key=lambda t: done.get(t[0].key, {}).get("states", float("inf")))

    def report(job: Job, r: dict) -> None:
        rec = _record(job, r)
        _keep(done, job.key, dict(rec), args.max_states)
        print(describe(job.setting, r, job.plan.name), flush=True)
        if sink is not None:
            sink.write(json.dumps({"key": job.key, **rec}) + "\n")
            sink.flush()

    estimate = (args.estimate_runs, args.estimate_above) if args.estimate_runs else None
    tasks = [(job.plan, *job.setting, args.max_states, args.task_seconds, need, args.python_optimum, args.policy_states,
              estimate) for job, need in todo]
    if args.workers > 1 and len(todo) > 1:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(args.workers) as pool:
            futures = {pool.submit(_task, t): job for t, (job, _) in zip(tasks, todo)}
            for f in as_completed(futures):
                report(futures[f], f.result())
    else:
        for t, (job, _) in zip(tasks, todo):
            report(job, _task(t))


# ------------------------------------------------------------------ the tables


def setting_name(visible: int, capacity: int | None, bin: str) -> str:
    return f"{bin}, {visible} visible, buffer {'unlimited' if capacity is None else capacity}"


POLICIES = ("paper", "bin-first", "slack", "lookahead", "fallback")
DEFAULT_POLICIES = ("lookahead", "paper")     # the fallback with --without-optimum (or --policies)
#: The tables' columns, in order, before any other policy asked for.
TABLE_POLICIES = ("lookahead", "fallback", "paper")
TABLE_HEAD = "| parts | setting | plans | skipped |"        # docs/policy-lab.md's table
README_HEAD = "| parts | settings measured |"               # how --readme finds the lab's table in a document
CLAIM_START = "Measured on "                                # the paragraph after it, written with it
LABELS = {"lookahead": "default", "fallback": "without its optimum", "paper": "paper's rule"}
CLAIM_LABELS = {"lookahead": "the default", "fallback": "the default without its optimum (`--without-optimum`)",
                "paper": "the paper's rule"}


def summarise(values: list[float]) -> tuple[float, float, float]:
    return statistics.mean(values), statistics.median(values), max(values)


def pct(x: float) -> str:
    """A gap in percent; a rounding error's minus sign on an exact 0 is not shown."""
    v = 100 * x
    return f"{0.0 if abs(v) < 5e-4 else v:+.3f}%"


@dataclass
class Cell:
    """One group in one setting: the records with the optimum, why the others were skipped, and each
    skipped plan's record (its largest attempt, with its state cap: :func:`largest_attempts`)."""
    rows: list
    skipped: list
    walls: dict = field(default_factory=dict)

    def gaps(self, name: str) -> list[float]:
        return [r["gaps"][name] for r in self.rows if name in r["gaps"]]


def largest_attempts(done: dict) -> dict[str, dict]:
    """Each plan-setting's skip at the largest state cap it was attempted with (by its key without the cap),
    that cap put in as ``cap``: what the tables give where no cap found the optimum (an exact result,
    filed under every cap by :func:`_keep`, wins over any skip)."""
    out: dict[str, dict] = {}
    for key, rec in done.items():
        prefix, cap = key.rsplit(":", 1)
        if "skipped" in rec and (prefix not in out or int(cap) > out[prefix]["cap"]):
            out[prefix] = {**rec, "cap": int(cap)}
    return out


def cells(jobs: list[Job], done: dict) -> dict[tuple[str, tuple], Cell]:
    """Every (group, setting) of the jobs, in the jobs' order, from the results: the optimum found at any
    state cap, else the skip at the largest cap attempted (:func:`largest_attempts`), else ``not run``."""
    out: dict[tuple[str, tuple], Cell] = {}
    walls = largest_attempts(done)
    for job in jobs:
        cell = out.setdefault((job.group, job.setting), Cell([], []))
        rec = done.get(job.key)
        if rec is None or "skipped" in rec:
            rec = walls.get(job.key.rsplit(":", 1)[0], {"skipped": "not run"})
        if "skipped" in rec:
            cell.skipped.append((job.plan.name, rec["skipped"]))
            cell.walls[job.plan.name] = rec
        else:
            cell.rows.append({**rec, "plan": job.plan.name})
    groups = list(dict.fromkeys(g for g, _ in out))
    return dict(sorted(out.items(), key=lambda kv: groups.index(kv[0][0])))     # a group's settings together


def _mean_max(values: list[float], n: int) -> str:
    if not values:
        return "— | —"
    mean, _, top = summarise(values)
    of = f" ({len(values)})" if len(values) < n else ""
    return f"{pct(mean)}{of} | {pct(top)}{of}"


def full_table(table: dict, names) -> list[str]:
    """docs/policy-lab.md's table: one row per group and setting."""
    head = TABLE_HEAD + " " + " | ".join(f"{n} mean | {n} max" for n in names) + " | optimum's states, largest |"
    lines = [head, "| --- | --- | ---: | ---: | " + " | ".join("---: | ---:" for _ in names) + " | ---: |"]
    for (group, setting), cell in table.items():
        n = len(cell.rows)
        states = f"{max(r['states'] for r in cell.rows):,}" if cell.rows else "—"
        lines.append(f"| {group} | {setting_name(*setting)} | {n} | {len(cell.skipped)} | "
                     + " | ".join(_mean_max(cell.gaps(p), n) for p in names) + f" | {states} |")
    return lines


def _why(reason: str) -> str:
    """A skip's kind, for grouping: the state cap, the time cap or not run."""
    return "over the state cap" if "states" in reason else "not run" if reason == "not run" else "over the time cap"


def skipped_text(table: dict) -> list[str]:
    """Each group-setting's skipped plans, grouped by why (with each plan's state count where it was over the cap)."""
    out = []
    for (group, setting), cell in table.items():
        if not cell.skipped:
            continue
        kinds: dict[str, list[str]] = {}
        for plan, why in cell.skipped:
            count = why.split(": ", 1)[1].split(" (")[0] if ": " in why else ""
            kinds.setdefault(_why(why), []).append(f"{plan} ({count})" if count else plan)
        out.append(f"- {group}, {setting_name(*setting)}: "
                   + "; ".join(f"{kind}: {', '.join(plans)}" for kind, plans in kinds.items()))
    return out


def missing_policies(table: dict, names) -> list[str]:
    """Each group-setting's plans with the optimum whose policy's evaluation was cut (time or states), and
    why; the plans a column lacks because it was not run are told by the counts in brackets."""
    out = []
    for (group, setting), cell in table.items():
        for p in names:
            left = [f"{r['plan']} ({r['policy_skipped'][p]})" for r in cell.rows
                    if p not in r["gaps"] and p in r.get("policy_skipped", {})]
            if left:
                out.append(f"- {group}, {setting_name(*setting)}, {p}: {', '.join(left)}")
    return out


def estimated_text(table: dict, names) -> list[str]:
    """Each gap estimated from seeded runs (``--estimate-runs``) rather than evaluated exactly: its standard
    error, the runs and looks, and the runs' own mean time (a second estimate of the same gap, wider)."""
    out = []
    for (group, setting), cell in table.items():
        for r in cell.rows:
            for p, e in r.get("estimated", {}).items():
                if p in names and p in r["gaps"]:
                    out.append(f"- {group}, {setting_name(*setting)}, {r['plan']}, {p}: {pct(e['gap'])}, standard "
                               f"error {100 * e['se']:.3f}% ({e['runs']:,} runs of seed {e['seed']}, {e['looks']:,} "
                               f"looks, {e['differing']:,} where its action is not the optimum's; the runs' own "
                               f"mean time {pct(e['cost_gap'])}, standard error {100 * e['cost_se']:.3f}%)")
    return out


def not_by_optimum(table: dict) -> list[str]:
    """The plan-settings where the default did not decide by its optimum, though the lab's optimum fits: its
    gap (or that its evaluation was cut) and why (its refusal; where the run did not record it, the optimum's
    states)."""
    out = []
    for (group, setting), cell in table.items():
        for r in cell.rows:
            cut = r.get("policy_skipped", {}).get("lookahead", "")
            # a line that records the default's CPU records whether it decided by its optimum (older ones neither)
            if "lookahead" in r["gaps"] and "lookahead" in r.get("cpu", {}) and "lookahead" not in r.get("by_optimum", []):
                why = r.get("refusals", {}).get("lookahead") or f"refusal not recorded; the optimum: {r['states']:,} states"
                out.append(f"- {group}, {setting_name(*setting)}, {r['plan']}: {pct(r['gaps']['lookahead'])} ({why})")
            elif "did not decide by its optimum" in cut:
                out.append(f"- {group}, {setting_name(*setting)}, {r['plan']}: its evaluation {cut}")
    return out


def _at_least(rec: dict) -> int | float | None:
    """A skip's proven lower bound on the optimum's states: recorded (``low``), or in a line written before
    it was, read from its reason (``'... at least 13,309,553)'``, ``'at least 3.5e+13'``)."""
    if rec.get("low"):
        return rec["low"]
    found = re.search(r"at least ([\d,]+(?:\.\d+)?(?:e\+\d+)?)", rec["skipped"])
    if found is None:
        return None
    text = found.group(1).replace(",", "")
    return float(text) if "e" in text or "." in text else int(text)


def wall_text(rec: dict) -> str:
    """Where a skipped plan-setting's optimum hit its wall, in words, from its largest attempt
    (:func:`largest_attempts`): over the state cap by the count before the work (certain where the count's
    lower bound is over it, else estimated), or cut during the work by its states or time with what it
    reached (:func:`wall_words`; lines written before that was recorded say so).

    >>> wall_text({"skipped": "optimum over 1800 s", "estimate": 51047008, "cap": 60000000})
    'over 1,800 s at the 60,000,000-state cap (about 51,047,008 states estimated; how far it got not recorded)'
    """
    why, cap = rec["skipped"], rec.get("cap")
    if cap is None:
        return why
    low, estimate = _at_least(rec), rec.get("estimate")
    about = f"about {big(estimate)} states estimated" if estimate else ""
    if ": " in why:                 # refused by the count before the work: nothing run
        if "(exact)" in why:
            return f"{big(estimate)} states (counted before the work), over the {cap:,}-state cap"
        if low is not None and low > cap:
            return f"over {cap:,} states: at least {big(int(low))} counted before the work ({about})"
        return (f"{about} before the work, over the {cap:,}-state cap (at least {big(int(low or 0))} counted); "
                "not run")
    cut = why.removeprefix("optimum ")
    if cut.endswith(" s"):
        cut = f"over {float(cut.split()[1]):,g} s at the {cap:,}-state cap"
    measured = wall_words(rec["measured"]) if "measured" in rec else "how far it got not recorded"
    return f"{cut} ({'; '.join(filter(None, [about, measured]))})"


#: What a skipped row of a single plan's table says (docs/policy-lab.md).
WALLS_TEXT = ("Each plan-setting as its largest attempt left it: the optimum found at any state cap, else where "
              "the attempt with the largest cap hit its wall: refused by the count before the work (certain where "
              "the count's lower bound is over the cap, else by the estimate, and not run), or cut during the work "
              "by its states or time, with the states it finished, its CPU seconds and the process's peak memory where the run "
              "recorded them.")


#: What a single plan's table says where a gap is estimated from runs (docs/policy-lab.md).
ESTIMATED_TEXT = ("A gap given with ± is estimated from seeded runs by the policy's regrets over the optimum "
                  "(`--estimate-runs`; unbiased, ± its standard error), not evaluated exactly.")


def single_table(table: dict, names) -> list[str]:
    """One plan per group (SALBP, the gearbox): its optimum and each policy's gap, or where its optimum hit
    the wall (:func:`wall_text`)."""
    lines = ["| plan | setting | optimum | states | " + " | ".join(names) + " |",
             "| --- | --- | ---: | ---: | " + " | ".join("---:" for _ in names) + " |"]
    for (_, setting), cell in table.items():
        for plan, why in cell.skipped:
            wall = wall_text(cell.walls[plan]) if plan in cell.walls else why
            lines.append(f"| {plan} | {setting_name(*setting)} | skipped: {wall} | — | " + " | ".join("—" for _ in names) + " |")
        for r in cell.rows:
            lines.append(f"| {r['plan']} | {setting_name(*setting)} | {r['optimum']:.4f} | {r['states']:,} | "
                         + " | ".join(_gap_or_cut(r, p) for p in names) + " |")
    return lines


def _gap_or_cut(r: dict, name: str) -> str:
    """A policy's gap in a single plan's row (estimated from runs: with its standard error), or where its
    evaluation was cut and how far it got."""
    est = r.get("estimated", {}).get(name)
    if name in r["gaps"] and est is not None:
        return f"{pct(r['gaps'][name])} ± {100 * est['se']:.3f}% ({est['runs']:,} runs)"
    if name in r["gaps"]:
        return pct(r["gaps"][name])
    if name not in r.get("policy_skipped", {}):
        return "—"
    measured = r.get("policy_measured", {}).get(name)
    return f"evaluation {r['policy_skipped'][name]}" + (f" ({wall_words(measured)})" if measured else "")


def _words(items: list) -> str:
    """``[1, 2, 3]`` → ``'1, 2 or 3'``."""
    items = [str(i) for i in items]
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " or " + items[-1]


def _capacity(c) -> str:
    return "unlimited" if c is None else str(c)


def _count(n: int, what: str) -> str:
    return f"{n:,} {what}{'s' * (n != 1)}"


def _span(values: list[int]) -> str:
    """``[1, 2, 3]`` → ``'1–3'``; ``[1, 3]`` → ``'1, 3'``."""
    if len(values) > 2 and values == list(range(values[0], values[-1] + 1)):
        return f"{values[0]}–{values[-1]}"
    return ", ".join(map(str, values))


def _settings_text(covered: list[tuple], settings: list[tuple]) -> str:
    """The settings measured, in words: every one asked for, or per bin the buffers and the parts visible
    (``'uniform: buffer 1, 2 with 1–3 visible, unlimited with 1 visible; pile: ...'``)."""
    if set(covered) == set(settings):
        return "every setting"
    out = []
    for b in dict.fromkeys(b for _, _, b in settings):
        by_visible: dict[tuple, list[str]] = {}
        for c in dict.fromkeys(c for _, c, _ in settings):
            vs = tuple(v for v in dict.fromkeys(v for v, _, _ in settings) if (v, c, b) in covered)
            if vs:
                by_visible.setdefault(vs, []).append(_capacity(c))
        if by_visible:
            out.append(f"{b}: buffer " + ", ".join(f"{', '.join(caps)} with {_span(list(vs))} visible"
                                                    for vs, caps in by_visible.items()))
    return "; ".join(out)


def _worst_mean(table: dict, keys, name: str) -> tuple[float, float] | None:
    """The largest of the settings' mean gaps and the largest gap, over the given (group, setting) cells."""
    means = [summarise(g)[0] for k in keys if (g := table[k].gaps(name))]
    tops = [max(g) for k in keys if (g := table[k].gaps(name))]
    return (max(means), max(tops)) if means else None


def readme_block(table: dict, groups: list[str], settings: list[tuple], args) -> str:
    """The README's table (one row per size: the settings measured, the default's worst setting's mean and
    its largest gap, the same without its optimum and for the paper's rule) and the claim under it."""
    names = TABLE_POLICIES
    lines = [README_HEAD + " plan-settings | skipped | "
             + " | ".join(f"{LABELS[n]}: mean (worst setting) | max" for n in names) + " |",
             "| --- | --- | ---: | ---: | " + " | ".join("---: | ---:" for _ in names) + " |"]
    for group in groups:
        keys = [(group, s) for s in settings]
        covered = [s for s in settings if table[(group, s)].gaps("lookahead")]
        rows = sum(len(table[k].rows) for k in keys)
        skipped = sum(len(table[k].skipped) for k in keys)
        cols = []
        for n in names:
            w = _worst_mean(table, keys, n)
            cols.append("— | —" if w is None else f"{pct(w[0])} | {pct(w[1])}")
        lines.append(f"| {group} | {_settings_text(covered, settings) if covered else 'none'} | {rows} | {skipped} | "
                     + " | ".join(cols) + " |")
    keys = [(g, s) for g in groups for s in settings]
    sizes = ", ".join(groups[:-1]) + f" and {groups[-1]}" if len(groups) > 1 else groups[0]
    vis = _words(sorted({v for v, _, _ in settings}))
    caps = _words([_capacity(c) for c in dict.fromkeys(c for _, c, _ in settings)])
    bins = " and the ".join(dict.fromkeys(b for _, _, b in settings))
    claim = [f"{CLAIM_START}{args.plans} random plans each of {sizes} parts (a third with two strategies), in the "
             f"settings each row names (of {vis} parts visible; {caps} buffer locations; the {bins} bin), on the plans "
             f"whose optimum's programme fits in {args.max_states:,} states:"]
    for n in names:
        w = _worst_mean(table, keys, n)
        if w is not None:
            count = sum(len(table[k].gaps(n)) for k in keys)
            claim.append(f"{CLAIM_LABELS[n]} within mean {pct(w[0])} (the worst setting's) and max {pct(w[1])} of the "
                         f"optimum over {_count(count, 'plan-setting')};")
    est = [e for k in keys for r in table[k].rows for p, e in r.get("estimated", {}).items()
           if p in names and p in r["gaps"]]
    if est:
        claim.append(f"{_count(len(est), 'gap')} of these estimated from seeded runs, not evaluated exactly "
                     f"(standard error at most {100 * max(e['se'] for e in est):.3f}%);")
    refused = not_by_optimum({k: table[k] for k in keys})
    if refused:
        claim.append(f"in {_count(len(refused), 'plan-setting')} the default did not decide by its optimum (its "
                     "count of the states was cut by the clock on the loaded machine);")
    skipped = sum(len(table[k].skipped) for k in keys)
    claim.append(f"{_count(skipped, 'plan-setting')} skipped (the optimum over the cap, or not yet run); each "
                 "listed in [docs/policy-lab.md](docs/policy-lab.md).")
    return "\n".join(lines) + "\n\n" + " ".join(claim) + "\n"


def replace_block(path: Path, text: str, head: str = README_HEAD) -> None:
    """Put ``text`` in place of the lab's table in ``path``: the Markdown table whose header starts with
    ``head``, with the paragraph after it that starts with :data:`CLAIM_START` (the table must be there)."""
    lines = path.read_text().split("\n")
    start = next((k for k, line in enumerate(lines) if line.startswith(head)), None)
    if start is None:
        raise SystemExit(f"{path}: no lab table (a line starting {head!r}); put one where the table goes")
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    if end + 1 < len(lines) and not lines[end] and lines[end + 1].startswith(CLAIM_START):
        end += 2
    path.write_text("\n".join(lines[:start] + text.rstrip("\n").split("\n") + lines[end:]))


def read_block(path: Path, head: str = README_HEAD) -> str:
    """The block :func:`replace_block` writes, as it stands in ``path``."""
    lines = path.read_text().split("\n")
    start = next(k for k, line in enumerate(lines) if line.startswith(head))
    end = start
    while lines[end].startswith("|"):
        end += 1
    return "\n".join(lines[start:end + 2]) + "\n"


def document(table: dict, groups: list[str], names, n_plans: int, done_cpu: float) -> str:
    """docs/policy-lab.md: the random plans' table per size and setting, what was skipped and why, the
    columns with fewer plans, then each single plan's (SALBP, the gearbox, a folder's) optimum and gaps."""
    random_cells = {k: c for k, c in table.items() if k[0] in groups}
    out = ["# The policy lab", "",
           "Written by `benchmarks/policy_lab.py --table` from `benchmarks/policy_lab_results.jsonl`; how it works: "
           "[the paper's comparison](comparison.md); how to run it: the script's docstring.", "",
           f"Gap of each policy's exact expected time to the optimum's, per size and setting, over {n_plans} random "
           "plans a size (a third with two strategies): the mean and the largest. `lookahead` is the default "
           "policy; `fallback` the default with its exact optimum switched off (`--without-optimum`): what "
           "decides where the optimum's programme does not fit; `paper` the paper's rule. Each decides without a "
           "decision budget (within one, the frontier windows keep their usual state caps: without one they hold "
           "more before a run's first installation, and in the pile with two buffer locations or more; "
           "`opportune.engine.tuning`). A plan-setting is "
           "skipped when the optimum's programme is over the lab's state cap (counted before the work) or time, "
           "or was not run, and listed below; a number in brackets is how many plans a column covers where "
           "fewer than the row's.", "", *full_table(random_cells, names)]
    if skips := skipped_text(random_cells):
        out += ["", "## Skipped", "", *skips]
    if refused := not_by_optimum(random_cells):
        out += ["", "## Where the default did not decide by its optimum", "",
                "The lab's optimum fits, but the default's own check did not let it decide (it lists the states "
                "within a second of wall-clock time, which a loaded machine may not give it); it then decided by "
                "its fallback:", "", *refused]
    if estimated := estimated_text(random_cells, names):
        out += ["", "## Gaps estimated from runs", "",
                "Where the optimum's programme fits but a policy's exact evaluation would take long (it asks the "
                "policy at every state and look it reaches: 1.2-1.9 million in the pile's largest rows, over an "
                "hour), its gap is estimated from seeded runs in the programme's own bin (`--estimate-runs`): each "
                "run adds up its regrets, the optimum's expected time "
                "after the policy's action less its least over the actions, at every look (0 wherever the policy "
                "does what the optimum does); their mean is an unbiased estimate of the gap "
                "(`opportune.policies.regret`). The table takes these estimates as the gaps:", "", *estimated]
    if left := missing_policies(random_cells, names):
        out += ["", "## Policies out of time or states", "", *left]
    for group in dict.fromkeys(g for g, _ in table):
        if group not in groups:
            part = {k: c for k, c in table.items() if k[0] == group}
            walls = [WALLS_TEXT, ""] if any(c.skipped for c in part.values()) else []
            if any(r.get("estimated") for c in part.values() for r in c.rows):
                walls += [ESTIMATED_TEXT, ""]
            out += ["", f"## {group}", "", *walls, *single_table(part, names)]
    out += ["", f"The results took {done_cpu / 3600:.1f} CPU hours (each plan-setting's optimum and policies)."]
    return "\n".join(out) + "\n"


def plot_sizes(path: Path, table: dict, groups: list[str], names) -> None:
    """One row per size: each policy's mean gap over every plan-setting (dot) and largest gap (end of its line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams["svg.fonttype"] = "none"
    fig, ax = plt.subplots(figsize=(7, 0.5 * len(groups) + 1.2), dpi=150)
    top = 0.3
    for j, name in enumerate(names):
        for i, group in enumerate(groups):
            values = [g for (gr, _), c in table.items() if gr == group for g in c.gaps(name)]
            if not values:
                continue
            mean, _, largest = summarise(values)
            top = max(top, 100 * largest)
            y = i + (j - (len(names) - 1) / 2) * 0.2
            ax.plot([100 * mean, 100 * largest], [y, y], color=f"C{j}", lw=1)
            ax.plot([100 * mean], [y], "o", color=f"C{j}", ms=3.5, label=name if i == 0 else None)
    ax.set_yticks(range(len(groups)), [f"{g} parts" for g in groups], fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("symlog", linthresh=0.01)
    ax.set_xlabel("gap to the optimum (%) over every setting measured: mean (dot) to largest (line end); "
                  "dashed: 0.3%", fontsize=8)
    ax.axvline(0, color="grey", lw=0.6)
    ax.axvline(0.3, color="grey", lw=0.6, ls="--")
    ticks = [t for t in (0, 0.01, 0.1, 0.3, 1, 3, 10, 30, 100) if t <= top * 1.5]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.tick_params(axis="x", labelsize=7)
    ax.set_xlim(-0.002, top * 1.5)
    ax.legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=len(names), frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata={"Date": None} if path.suffix == ".pdf" else None)
    plt.close(fig)
    print(f"wrote {path}")


PAIRED = ("paper", "bin-first", "slack", "lookahead", "rollout")


def paired(spec: str, args) -> None:
    """Every policy on the same random bins of a plan too large for exact evaluation: the mean time, and
    the mean difference from the paper's rule with its 95% interval."""
    from opportune.study.report import summary
    from opportune.study.simulate import StudyConfig, run_study

    plan = load_plan(spec)
    start = time.perf_counter()
    result = run_study(StudyConfig(plan, strategies=PAIRED, trials=args.paired_trials, seed=args.seed,
                                   visible=args.paired_visible), workers=args.workers)
    doc = summary(result)["strategies"]
    print(f"\n{plan.name} ({plan.n_units} units): paired Monte Carlo, {args.paired_trials} trials per policy "
          f"on the same bins, uniform bin, {args.paired_visible} visible, unlimited buffer "
          f"({time.perf_counter() - start:.0f} s)")
    print(f"  {'policy':<10} {'mean time':>10}  {'against paper (95% interval)':>32}  {'s/trial':>8}")
    for name in PAIRED:
        s = doc[name]
        against = s.get("paired")
        text = "—" if against is None else \
            f"{against['mean_difference']:+.3f} ({against['ci95'][0]:+.3f} .. {against['ci95'][1]:+.3f})"
        per = result.seconds.get(name, 0.0) / max(1, s["trials"])
        print(f"  {name:<10} {s['time']['mean']:>10.3f}  {text:>32}  {per:>8.3f}")
    if args.bound:      # the best any online policy can do is at least this (opportune.study.bounds)
        from opportune.study.bounds import describe_gaps, lower_bound, policy_gaps

        b = lower_bound(plan, visible=args.paired_visible, trials=min(args.paired_trials, 100), seed=args.seed)
        print(f"  lower bound on any online policy: {b.mean:.3f} ± {b.half_width:.3f} (95%; {b.method}); each "
              "mean against it: " + describe_gaps(policy_gaps(b, {n: doc[n]["time"] for n in PAIRED})))


# ------------------------------------------------------------------ the command


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=30, help="random plans a size")
    ap.add_argument("--sizes", default="8-12,16,20,25,30",
                    help="parts of the random plans, comma-separated groups: N, or LOW-HIGH (drawn)")
    ap.add_argument("--min-parts", type=int, help="one group of LOW to HIGH parts (with --max-parts) instead of --sizes")
    ap.add_argument("--max-parts", type=int)
    ap.add_argument("--salbp", default="KILBRID,TONGE70,ARC111",
                    help="SALBP graphs in every setting, comma-separated (skipped with their states where over the cap)")
    ap.add_argument("--plans-dir", type=Path, help="also every plan file in this folder (.yaml, .json, .IN2, ...)")
    ap.add_argument("--visible", default="1,2,3", help="parts visible per look, comma-separated")
    ap.add_argument("--capacities", default="1,2,3,inf", help="buffer capacities, comma-separated (inf: unlimited)")
    ap.add_argument("--bins", default="uniform,pile", help="bins, comma-separated (uniform, pile)")
    ap.add_argument("--policies", default=",".join(DEFAULT_POLICIES),
                    help=f"policies evaluated against the optimum, comma-separated ({', '.join(POLICIES)})")
    ap.add_argument("--without-optimum", action="store_true",
                    help="also the default policy with its exact optimum switched off (the column 'fallback'): "
                         "its fallback measured where the optimum is known")
    ap.add_argument("--only", default="", help="only these plans (names, comma-separated: r3-11, gearbox, ...)")
    ap.add_argument("--python-optimum", action="store_true",
                    help="the optimum by the Python programme (the same values as the compiled core, 20-46x later)")
    ap.add_argument("--compiled-optimum", action="store_true", help="the optimum by the compiled core (the default)")
    ap.add_argument("--max-states", type=int, default=2_000_000, help="states of one exact programme, at most")
    ap.add_argument("--policy-states", type=int,
                    help="states of one policy's evaluation, at most (counted work: the same cut whatever the load; "
                         "default: --max-states); past it the policy is left out of that plan-setting's column")
    ap.add_argument("--estimate-runs", type=int, default=0,
                    help="where the optimum has more than --estimate-above states, estimate each policy's gap from "
                         "this many seeded runs by its regrets over the optimum (unbiased; its standard error "
                         "recorded and listed) instead of evaluating it exactly (0: always exactly)")
    ap.add_argument("--estimate-above", type=int, default=1_000_000,
                    help="the optimum's states past which --estimate-runs applies")
    ap.add_argument("--cheapest-first", action="store_true",
                    help="run the plan-settings in order of the optimum's states --results has for them (those it "
                         "lacks last): the most columns filled in a short run")
    ap.add_argument("--task-seconds", type=float, default=300.0,
                    help="seconds for the optimum of one plan in one setting, and for each policy's evaluation, at most")
    ap.add_argument("--workers", type=int, default=1, help="worker processes (plans x settings, and the paired studies)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, help="append every plan-setting's result here (JSON lines) and skip "
                    "those already there: an interrupted run goes on where it stopped")
    ap.add_argument("--redo-skipped", action="store_true", help="run again the plan-settings --results has as skipped")
    ap.add_argument("--no-run", action="store_true", help="run nothing: the tables from --results alone")
    ap.add_argument("--table", type=Path, help="write the tables in Markdown here")
    ap.add_argument("--readme", type=Path, help="replace the lab's table and claim in this file (found by its header)")
    ap.add_argument("--plot", type=Path, help="write the gap per size here (PNG or PDF)")
    ap.add_argument("--paired", default="salbp:KILBRID,salbp:TONGE70",
                    help="plans compared by paired Monte Carlo (comma-separated; empty: none)")
    ap.add_argument("--paired-trials", type=int, default=200)
    ap.add_argument("--paired-visible", type=int, default=2, help="parts visible per look in the paired studies")
    ap.add_argument("--bound", action="store_true",
                    help="also a certified lower bound on any online policy beside the paired studies' means")
    return ap


def _args(argv) -> argparse.Namespace:
    ap = parser()
    args = ap.parse_args(argv)
    args.policies = tuple(p for p in args.policies.split(",") if p)
    if args.without_optimum and "fallback" not in args.policies:
        args.policies += ("fallback",)
    unknown = set(args.policies) - set(POLICIES)
    if unknown or not args.policies:
        ap.error(f"--policies: unknown {', '.join(sorted(unknown)) or '(none given)'}; choose from {', '.join(POLICIES)}")
    if args.min_parts is not None or args.max_parts is not None:
        lo = args.min_parts if args.min_parts is not None else args.max_parts
        args.sizes = f"{lo}-{args.max_parts if args.max_parts is not None else lo}"
    try:
        args.size_groups = parse_sizes(args.sizes)
        args.settings = [(v, None if c == "inf" else int(c), b) for b in args.bins.split(",")
                         for v in map(int, args.visible.split(",")) for c in args.capacities.split(",")]
    except ValueError as exc:
        ap.error(f"--sizes, --visible or --capacities: not a number ({exc})")
    args.error = ap.error
    return args


def make_jobs(args) -> tuple[list[Job], list[str]]:
    """Every plan in every setting (the random groups first, then SALBP, the folder, the gearbox), and the
    random groups' labels."""
    plans: list[tuple[str, object, bool]] = []
    groups = []
    for lo, hi in args.size_groups:
        groups.append(size_label(lo, hi))
        plans += [(f"{lo}-{hi}", plan, two) for plan, two in generate(args.seed, args.plans, lo, hi)]
    plans += [("salbp", load_plan(f"salbp:{name}"), False) for name in filter(None, args.salbp.split(","))]
    if args.plans_dir is not None:
        for path in sorted(args.plans_dir.iterdir()):
            if path.is_file() and not path.name.startswith("."):
                plan = load_plan(path)
                plans.append(("folder", plan, len(plan.strategies) > 1))
    if args.plans and args.size_groups:     # the gearbox beside the first group, as it always was
        lo, hi = args.size_groups[0]
        plans.append((f"{lo}-{hi}", load_plan(GEARBOX), False))
    only = {name for name in args.only.split(",") if name}
    unknown = only - {plan.name for _, plan, _ in plans}
    if unknown:
        args.error(f"--only: no plan named {', '.join(sorted(unknown))}; the plans are "
                   f"{', '.join(dict.fromkeys(p.name for _, p, _ in plans))}")
    labels = {f"{lo}-{hi}": size_label(lo, hi) for lo, hi in args.size_groups}
    jobs = []
    for setting in args.settings:
        for tag, plan, two in plans:
            if only and plan.name not in only:
                continue
            group = {"salbp": "SALBP", "folder": "The folder"}.get(tag) or labels[tag]
            if plan.name == "gearbox":
                group = "The gearbox"
            jobs.append(Job(_key(args.seed, tag, plan, setting, args.max_states), group, plan, setting, two))
    return jobs, groups


def print_table(table: dict, groups: list[str], names) -> None:
    print("\ngap to the optimum, mean / max (%), over the plans evaluated")
    print(f"  {'parts':<6} {'setting':<36} {'plans':>5} {'skipped':>7}  " + "  ".join(f"{n:>17}" for n in names))
    for (group, setting), cell in table.items():
        if group in groups:
            print(f"  {group:<6} {setting_name(*setting):<36} {len(cell.rows):>5} {len(cell.skipped):>7}  "
                  + "  ".join(f"{100 * summarise(g)[0]:>+8.3f} {100 * summarise(g)[2]:>+8.3f}" if (g := cell.gaps(n))
                              else f"{'—':>17}" for n in names))


def main(argv=None) -> int:
    args = _args(argv)
    jobs, groups = make_jobs(args)
    done = read_results(args.results, args.max_states)
    t0 = time.perf_counter()
    if not args.no_run:
        sink = None if args.results is None else args.results.open("a")
        try:
            _run_jobs(jobs, args, done, sink)
        finally:
            if sink is not None:
                sink.close()
        print(f"\n{time.perf_counter() - t0:.0f} s")
    names = list(TABLE_POLICIES) + [p for p in args.policies if p not in TABLE_POLICIES]
    table = cells(jobs, done)
    print_table(table, groups, names)
    cpu = sum(sum(done[j.key].get("cpu", {}).values()) for j in jobs if j.key in done)
    if args.table:
        args.table.parent.mkdir(parents=True, exist_ok=True)
        args.table.write_text(document(table, groups, names, args.plans, cpu))
        print(f"wrote {args.table}")
    if args.readme:
        replace_block(args.readme, readme_block(table, groups, args.settings, args))
        print(f"wrote the lab's table into {args.readme}")
    if args.plot:
        plot_sizes(args.plot, table, groups, names)
    for spec in filter(None, args.paired.split(",")):
        paired(spec, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
