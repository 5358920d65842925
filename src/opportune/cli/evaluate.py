"""``evaluate``: the exact expected cost of a policy and of the optimum, by a dynamic programme (no Monte
Carlo error).

The programmes are :mod:`opportune.policies`' (:mod:`~opportune.policies.evaluate`, the pile's in
:mod:`~opportune.policies.pile`); what is here is option plumbing, the refusal of a plan too large before
any work (its states counted or estimated first), the progress bar and the report.

Imports: typer only; the programmes load when the command runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from opportune.cli.common import PLAN_ARG, err, fail, json_option, load_or_exit, out, policy_names
from opportune.limits import MAX_BUFFER, MAX_ESTIMATE_RUNS

# What each programme is, in the messages (by the first word of its key in EVALUATE_RATES).
_WORDS = {"compiled": "the compiled optimum", "Python": "the optimum in Python (no compiled core)",
          "rule": "the policy's own evaluation, look by look in Python",
          "window": "the policy's own evaluation with its look-ahead, look by look in Python"}


def default_cap(programme: str) -> int:
    """The states ``programme`` (a key of :data:`~opportune.engine.tuning.EVALUATE_RATES`) may store
    by default: what it does in :data:`~opportune.engine.tuning.EVALUATE_SECONDS` of CPU at its measured
    rate, within :data:`~opportune.engine.tuning.EVALUATE_MEMORY` of its states.  O(1).

    Parameters
    ----------
    programme : str
        ``"compiled uniform"``, ``"Python pile"``, ``"rule uniform"``, ...

    Returns
    -------
    int
        The state cap.

    Examples
    --------
    >>> default_cap("compiled uniform") > 100 * default_cap("rule uniform")
    True
    """
    from opportune.engine.tuning import EVALUATE_BYTES, EVALUATE_MEMORY, EVALUATE_RATES, EVALUATE_SECONDS

    kind = "compiled" if programme.startswith("compiled") else "Python"
    return min(EVALUATE_SECONDS * EVALUATE_RATES[programme], EVALUATE_MEMORY // EVALUATE_BYTES[kind])


def evaluate(
    plan_file: Path = PLAN_ARG,
    policy: str = typer.Option("lookahead", "--policy",
                               help="The policy to evaluate: lookahead (the default policy), paper "
                                    "(the paper's rule), bin-first, slack, rollout, buffer, shake or quantify"),
    bin_model: Optional[str] = typer.Option(None, "--bin", help="uniform, weighted or pile (default: plan, else uniform)"),
    visible: Optional[int] = typer.Option(None, "--visible", min=1, help="Parts seen per look (default: plan, else 2)"),
    buffer_capacity: Optional[int] = typer.Option(None, "--buffer-capacity", min=0, max=MAX_BUFFER,
                                                  help="Buffer locations (default: plan, else unlimited)"),
    max_states: Optional[int] = typer.Option(
        None, "--max-states", min=1,
        help="Most states of each programme (default: what it does in about a minute of CPU at its measured "
             "rate, within 2 GB: millions of states for the compiled optimum, about a hundred thousand for a "
             "policy's own evaluation in Python, which the look-ahead needs none of where it decides by the "
             "optimum; docs/comparison.md lists them).  The states are counted or estimated before any work, a "
             "plan whose optimum is over the limit is refused at once with the time and memory it would take, "
             "and a policy's evaluation stops at it saying how far it got"),
    time_limit: Optional[float] = typer.Option(None, "--time-limit", min=0.0,
                                               help="Stop the programme after this many seconds and say how far it "
                                                    "got (default: none; --max-states bounds the work)"),
    without_optimum: bool = typer.Option(False, "--without-optimum",
                                         help="The default policy (lookahead) with its exact optimum switched off: "
                                              "it decides by its fallback (the exact optimum of a frontier window of "
                                              "the plan, the rest lumped, in its bin), measured against the optimum"),
    runs: int = typer.Option(0, "--runs", min=0, max=MAX_ESTIMATE_RUNS,
                             help="Estimate the policy's gap from this many seeded runs by its regrets over the exact "
                                  "optimum, instead of evaluating the policy exactly (unbiased, with its standard "
                                  "error; for a policy whose own evaluation takes too long: the optimum must still "
                                  f"fit --max-states).  At least 2, at most {MAX_ESTIMATE_RUNS:,}; 0: exact"),
    seed: int = typer.Option(0, "--seed", min=0, help="The runs' seed (with --runs)"),
    as_json: bool = json_option(),
):
    """Exact expected cost of a policy and of the optimum (a dynamic programme, no Monte Carlo error).

    The states the programme needs are counted (or estimated, on large plans) first: a plan over --max-states is
    refused before any work, with the figure.  On a terminal a progress bar shows states done / expected.
    With --runs the policy's gap is estimated from seeded runs instead (the optimum exact)."""
    from opportune.engine import OrderEngine

    plan = load_or_exit(plan_file, json_errors=as_json, ways=True)    # a policy that does not take it: refused below
    chosen_bin = bin_model or plan.simulation.get("bin", "uniform")
    policy = _evaluated_policy(policy, chosen_bin, without_optimum, as_json)
    if runs == 1:
        fail("--runs 1: an estimate needs at least 2 runs (for its standard error); 0 evaluates exactly", 2,
             as_json=as_json)
    engine = OrderEngine(plan)
    config = _evaluation_config(plan, policy, chosen_bin, visible, buffer_capacity, max_states)
    sized = _optimum_engine(engine, config)
    work = _Work(sized, config, policy, without_optimum, max_states)
    run = _Run(plan, policy, chosen_bin, work, time_limit, _estimate(sized, config, work))
    run.sized, run.runs, run.seed = sized, runs, seed
    run.solve(engine, config, without_optimum, as_json)
    doc = {"plan": plan.name, "policy": policy, "bin": chosen_bin, "visible": config.visible,
           "buffer_capacity": config.buffer_capacity, "expected_time": run.value, "optimal": run.best,
           "ratio": run.value / run.best if run.best else None, "states": run.states,
           "policy_states": run.policy_states, "estimated_states": run.estimate.states,
           "estimate_exact": run.estimate.exact, "estimated_policy_states": run.policy_bound,
           "buffer_order_kept": run.ordered, "policy_by_optimum": bool(run.by_optimum),
           "without_optimum": without_optimum, "estimated": _estimated_doc(run.estimated)}
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
    value, best = run.value, run.best
    out().print(f"{plan.name}: {chosen_bin} bin, {config.visible} visible, buffer {cap}")
    out().print(f"  {policy}{' (its exact optimum switched off)' * without_optimum}: expected time {value:.4f}"
                + _estimated_words(run.estimated))
    out().print(f"  optimum: expected time {best:.4f}")
    reached = ("the policy decides by the optimum's values, so its value is the optimum's"
               if doc["policy_by_optimum"] else f"{run.policy_states:,} reached by the policy"
               if run.estimated is None else f"{run.estimated.looks:,} looks decided by the policy in the runs")
    out().print(f"  ratio {value / best:.5f} ({100 * (value / best - 1):+.2f}%); "
                f"{run.states:,} states for the optimum, {reached}")


def _estimated_doc(est) -> Optional[dict]:
    """The estimate's figures for ``--json`` (None: the policy was evaluated exactly)."""
    if est is None:
        return None
    return {"runs": est.runs, "seed": est.seed, "gap": est.gap, "standard_error": est.se,
            "expected_time_standard_error": est.se * est.optimum, "looks": est.looks, "looks_off_optimum": est.differing,
            "runs_mean_time": est.cost, "runs_mean_time_standard_error": est.cost_se}


def _estimated_words(est) -> str:
    """`` ± 0.0135, estimated from 1,000 seeded runs (...)`` after the policy's expected time ('' when exact)."""
    if est is None:
        return ""
    return (f" ± {est.se * est.optimum:.4f} (standard error), estimated from {est.runs:,} runs of seed {est.seed} by "
            f"its regrets over the optimum ({est.differing:,} of {est.looks:,} looks not the optimum's action)")


def _evaluated_policy(policy: str, chosen_bin: str, without_optimum: bool, as_json: bool) -> str:
    """The policy's name now, or exit with what to do when it, or the bin, cannot be evaluated exactly."""
    from opportune.study.simulate import ALL_STRATEGIES, OPTIMAL_BINS

    if chosen_bin not in OPTIMAL_BINS:
        fail(f"exact evaluation is defined for the uniform, weighted and pile bins, not '{chosen_bin}': use "
             f"`opportune simulate --bin {chosen_bin}` for a Monte Carlo estimate", 2)
    unsuitable = ("optimal", "random", "pallet", "kitting")
    policy = policy_names([policy])[0]
    if policy not in ALL_STRATEGIES or policy in unsuitable:
        fail(f"unknown or unsuitable policy '{policy}': choose from "
             f"{', '.join(s for s in ALL_STRATEGIES if s not in unsuitable)} (the optimum is printed beside it; "
             "random has no single decision rule; pallet and kitting do not draw from the bin)", 2)
    if without_optimum and policy != "lookahead":
        fail(f"--without-optimum switches off the exact optimum of the default policy (lookahead); '{policy}' has "
             "none: drop the option, or use --policy lookahead", 2, as_json=as_json)
    return policy


def _evaluation_config(plan, policy: str, chosen_bin: str, visible: Optional[int], buffer_capacity: Optional[int],
                       max_states: int):
    """The evaluation's settings (the plan's where the command line says nothing), or exit saying what is wrong."""
    from opportune.study.simulate import StudyConfig, StudyError
    from opportune.worlds import TimeModel

    sim = plan.simulation
    if buffer_capacity is None:
        buffer_capacity = sim.get("buffer_capacity")
    try:
        return StudyConfig(plan=plan, strategies=(policy,), trials=1, bin=chosen_bin,
                           visible=visible or sim.get("visible", 2), buffer_capacity=buffer_capacity,
                           costs=TimeModel.from_plan(plan),
                           optimal_states=max_states or default_cap("compiled uniform")).validate()
    except (StudyError, ValueError) as exc:
        fail(str(exc))


def _simulate_hint(chosen_bin: str) -> str:
    """The command that estimates what the exact evaluation cannot reach."""
    return f"`opportune simulate{' --bin pile' if chosen_bin == 'pile' else ''}`"


def _optimum_engine(engine, config):
    """The engine whose states the optimum's programme stores: the plan's with its interchangeable parts
    merged (fewer states, the same values; the compiled programme's 64-bit state codes need it on plans of
    many distinct parts), except in the pile, whose programme takes the plan as it is."""
    if config.bin == "pile":
        return engine
    from opportune.policies.optimal import optimum_engine

    return optimum_engine(engine, config.costs, config.weights if config.bin == "weighted" else None)


class _Work:
    """What the evaluation will run, sized before it starts: the optimum's programme (compiled or in Python)
    and the policy's own evaluation (none where the look-ahead decides by the optimum), each with its
    measured speed and bytes (:data:`~opportune.engine.tuning.EVALUATE_RATES`) and its state cap
    (``--max-states`` for both where given, else each its own :func:`default_cap`)."""

    def __init__(self, engine, config, policy: str, without_optimum: bool, max_states: Optional[int]):
        pile, weights = config.bin == "pile", config.weights if config.bin == "weighted" else None
        weighted = bool(weights) and len(set(weights.values())) > 1
        self.bin = "pile" if pile else "weighted" if weighted else "uniform"
        self.optimum = f"{'compiled' if self._compiled(engine, config, weights) else 'Python'} {self.bin}"
        # the look-ahead and the rollout decide by a programme of their own at every state: slower than a rule
        self.policy = f"{'window' if policy in ('lookahead', 'rollout') else 'rule'} {'pile' if pile else 'uniform'}"
        self.given = max_states is not None
        self.optimum_cap = max_states or default_cap(self.optimum)
        self.policy_cap = max_states or default_cap(self.policy)
        # the look-ahead decides by its own optimum where it fits its cap, in a uniform bin or the pile (not a
        # weighted bin whose weights differ): then it has no states of its own to evaluate
        self.lookahead_cap = None
        if policy == "lookahead" and not without_optimum and self.bin != "weighted":
            from opportune.policies.lookahead import Lookahead

            compiled = self.optimum.startswith("compiled")
            self.lookahead_cap = Lookahead.COMPILED_STATES if compiled else Lookahead().max_states

    @staticmethod
    def _compiled(engine, config, weights) -> bool:
        if config.bin == "pile":
            from opportune.policies.pile import compiled_pile_available

            return compiled_pile_available(engine)
        from opportune.policies.optimal import compiled_optimal_available

        return compiled_optimal_available(engine, weights, visible=config.visible)

    def seconds(self, programme: str, states: int) -> float:
        """The CPU seconds ``programme`` takes for ``states`` states, at its measured rate."""
        from opportune.engine.tuning import EVALUATE_RATES

        return states / EVALUATE_RATES[programme]

    def optimum_words(self, states: int) -> str:
        """``'the compiled optimum: 2 s of CPU at ~300,000 states/s and about 180 MB'``."""
        from opportune.engine.tuning import EVALUATE_BYTES, EVALUATE_RATES
        from opportune.policies.states import big

        kind = self.optimum.split()[0]
        return (f"{_WORDS[kind]}: {_duration(self.seconds(self.optimum, states))} of CPU "
                f"at ~{EVALUATE_RATES[self.optimum]:,} states/s and about "
                f"{big(max(1, states * EVALUATE_BYTES[kind] // 10**6))} MB")

    def limit(self, cap: int, programme: str) -> str:
        """``'--max-states 1,000'``, or the default cap and what it is."""
        from opportune.engine.tuning import EVALUATE_SECONDS

        if self.given:
            return f"--max-states {cap:,}"
        return f"--max-states {cap:,} (the default for {_WORDS[programme.split()[0]]}: ~{EVALUATE_SECONDS} s of CPU)"

    def by_optimum(self, estimate) -> Optional[bool]:
        """Whether the policy will decide by the optimum (so evaluating it is the optimum's work alone): True,
        False, or None when the count cannot tell (the estimate straddles the look-ahead's cap)."""
        if self.lookahead_cap is None:
            return False
        if estimate.low > self.lookahead_cap:
            return False
        return True if estimate.exact or estimate.states <= self.lookahead_cap else None

    def policy_words(self, estimate) -> str:
        """The policy's own evaluation, as a refusal quotes it."""
        from opportune.engine.tuning import EVALUATE_RATES

        by = self.by_optimum(estimate)
        if by:
            return "the policy decides by the optimum (its value is the optimum's: nothing more to evaluate)"
        rate, cap = EVALUATE_RATES[self.policy], self.policy_cap
        words = (f"{_WORDS[self.policy.split()[0]]} stops at {cap:,} states "
                 f"({_duration(self.seconds(self.policy, cap))} of CPU at ~{rate:,} states/s)")
        if by is None:
            return (f"the policy decides by the optimum where it has at most {self.lookahead_cap:,} states; "
                    f"else {words}")
        return f"then {words}"


def _estimate(engine, config, work: _Work):
    """The states the evaluation needs, counted or estimated before any (a few seconds at most, and far cheaper
    per state than the programme); exit with the figure when they are out of reach or over the optimum's cap."""
    from opportune.engine.tuning import EVALUATE_LIST_ON
    from opportune.policies.optimal import LOOK_CACHE_LOOKS
    from opportune.policies.states import estimate_states

    plan, chosen_bin = config.plan, config.bin
    estimate = estimate_states(engine, visible=config.visible, capacity=config.buffer_capacity,
                               pile=chosen_bin == "pile", stop_above=work.optimum_cap, time_limit=3.0)
    if not estimate.exact and estimate.low <= work.optimum_cap < estimate.states <= EVALUATE_LIST_ON * work.optimum_cap:
        # over the cap by the estimate alone (the listing ran out of its seconds, as on a loaded machine): the
        # listing goes on by counted work up to the cap, so the answer is the same however loaded
        estimate = estimate_states(engine, visible=config.visible, capacity=config.buffer_capacity,
                                   pile=chosen_bin == "pile", stop_above=work.optimum_cap, time_limit=None)
    if estimate.looks > LOOK_CACHE_LOOKS:
        fail(f"the exact evaluation of {plan.name} would weigh {estimate.looks:,} distinct looks at every state "
             f"({plan.n_units:,} parts, {config.visible} visible), more than the {LOOK_CACHE_LOOKS:,} the programme "
             f"keeps: it is out of reach whatever --max-states; estimate it by Monte Carlo with "
             f"{_simulate_hint(chosen_bin)}")
    if estimate.over(work.optimum_cap):
        figure = max(estimate.states, estimate.low)
        fail(f"the exact evaluation of {plan.name} needs {estimate.describe()} states for the optimum, more than "
             f"{work.limit(work.optimum_cap, work.optimum)}; {work.optimum_words(figure)}; "
             f"{work.policy_words(estimate)}.  Raise --max-states, reduce --buffer-capacity or --visible, or "
             f"estimate it by Monte Carlo with {_simulate_hint(chosen_bin)}")
    return estimate


class _Run:
    """One evaluation: its request, its programmes (the policy's and the optimum's; kept as they are made, so
    that a stop can say how far they got) and what they found.  (A plain class: ``dataclasses`` is not
    loaded at the command line's start-up for this one.)"""

    def __init__(self, plan, policy: str, chosen_bin: str, work: _Work, time_limit: Optional[float], estimate):
        self.plan, self.policy, self.chosen_bin, self.estimate = plan, policy, chosen_bin, estimate
        self.work, self.time_limit = work, time_limit
        self.running = "optimum"      # which programme runs (the policy's own evaluation, or the optimum's)
        self.ev = self.optimum = None
        self.sized = None       # the engine the optimum's states were counted on (the plan's, merged)
        self.policy_bound, self.ordered, self.by_optimum = 0, False, False
        self.runs, self.seed, self.estimated = 0, 0, None     # --runs: the gap estimated (a GapEstimate)
        self.value = self.best = 0.0
        self.states = self.policy_states = 0

    def solve(self, engine, config, without_optimum: bool, as_json: bool) -> None:
        """Run the programmes, or exit saying why they stopped and how far they got."""
        from opportune.engine.deadline import Deadline
        from opportune.policies.evaluate import PolicyStuck
        from opportune.policies.optimal import OptimalTooLarge, OutOfTime
        from opportune.policies.states import big
        from opportune.study.simulate import StrategyUnavailable, StudyError, make_policy, prepare

        plan, estimate = self.plan, self.estimate
        until = Deadline.after(self.time_limit)
        self.policy_bound = estimate.states
        try:
            chosen = make_policy(self.policy, engine, config, prepare(config, engine))
            if without_optimum:
                chosen.optimal = False      # the look-ahead's own setting: its fallback decides
            self._programmes(engine, chosen, config, until, as_json)
        except (OptimalTooLarge, OutOfTime) as exc:
            work = self.work
            cap = work.policy_cap if self.running == "policy" else work.optimum_cap
            why = (f"passed --time-limit {self.time_limit:g} s" if isinstance(exc, OutOfTime)
                   else f"needed more than {work.limit(cap, getattr(work, self.running))} states for the "
                        f"{self.running}")
            bound = (f", at most {big(self.policy_bound)} for the policy"
                     if self.policy_bound not in (0, estimate.states) else "")
            fail(f"the exact evaluation of {plan.name} {why}: it stopped after "
                 f"{_how_far(self.ev, self.optimum, self.chosen_bin)} of {estimate.describe()} expected for the "
                 f"optimum{bound}; raise the limit, or estimate it by Monte Carlo with "
                 f"{_simulate_hint(self.chosen_bin)}")
        except StrategyUnavailable:
            fail(f"the exact evaluation of {plan.name} ({plan.n_units} parts) is out of reach: the policy's first "
                 "decision alone does not finish in 10 s, and the states to evaluate grow exponentially with the "
                 "parts (up to --max-states); estimate it with `opportune simulate --strategies "
                 f"{self.policy} --decision-budget 0.05`")
        except (PolicyStuck, StudyError, ValueError) as exc:
            fail(str(exc))

    def _declared(self, engine, config):
        """The optimum's states on the plan as declared (its interchangeable parts not merged): they bound a
        policy's; counted as the merged plan's were (the same estimate where nothing merges)."""
        from opportune.policies.states import estimate_states

        if self.sized is engine:
            return self.estimate
        return estimate_states(engine, visible=config.visible, capacity=config.buffer_capacity,
                               stop_above=self.work.optimum_cap, time_limit=3.0)

    def _programmes(self, engine, chosen, config, until, as_json: bool) -> None:
        """Make the policy's programme and the optimum's, say how many states they may reach, and run them."""
        from opportune.policies.evaluate import PolicyEvaluator
        from opportune.policies.states import big

        estimate, pile, work = self.estimate, self.chosen_bin == "pile", self.work
        settings = dict(visible=config.visible, capacity=config.buffer_capacity, costs=config.costs)
        if pile:
            from opportune.policies.pile import PileSolver, pile_solver

            # the optimum compiled where the core is built (the same values): the policy's programme in Python
            self.ev = PileSolver(engine, chosen, max_states=work.policy_cap, **settings)
            self.optimum = pile_solver(engine, max_states=work.optimum_cap, **settings)
            if estimate.exact:
                self.optimum.reserve(estimate.states)    # a compiled table sized at once: it never doubles
        else:
            weights = config.weights if self.chosen_bin == "weighted" else None
            self.ev = PolicyEvaluator(engine, chosen, weights=weights, max_states=work.optimum_cap, **settings)
            self.ev.max_policy_states, self.ev.merge_optimum = work.policy_cap, True
        ev = self.ev
        ev.deadline = until         # finding where the buffer's order decides counts options: within it too
        if hasattr(chosen, "deadline"):    # a policy with a programme of its own (the look-ahead) stops too, its
            chosen.deadline = until        # listing of the optimum's states (asked next) included
        # a policy deciding by the optimum is worth the optimum: none of its own states are evaluated (in the
        # pile, the look-ahead says so itself: the pile's evaluator does not ask)
        decides = getattr(chosen, "decides_by_optimum", None)
        by_optimum = self.by_optimum = (ev.takes_optimum() if not pile else decides is not None and decides(
            engine, config.visible, config.buffer_capacity, config.costs, pile=True))
        if self.runs and not by_optimum:
            self._estimate_gap(engine, chosen, config, until, as_json)
            return
        if by_optimum:
            self.policy_bound, self.ordered = 0, False
        else:       # the policy's states are the plan's as declared: they are bounded by its count
            self.policy_bound, self.ordered = ev.states_bound(self._declared(engine, config).states), ev.ordered
        kept = "its buffer kept in the order of buffering; " if self.ordered else ""
        optimum = f"states: {estimate.describe()} for the optimum ({work.optimum_words(estimate.states)})"
        if not as_json and by_optimum:
            out().print(f"{optimum}; none for the policy (it decides by the optimum's values: its value is the "
                        "optimum's)")
        elif not as_json:
            # a bound, not a count: the policy reaches a part of these states (it stops at its cap if not)
            reach = min(self.policy_bound, work.policy_cap)
            out().print(f"{optimum}; at most {big(self.policy_bound)} for the policy ({kept}"
                        f"{_WORDS[work.policy.split()[0]]}: at most {_duration(work.seconds(work.policy, reach))} "
                        "of CPU)" + (f"; it stops if it passes {work.limit(work.policy_cap, work.policy)}"
                                     if self.policy_bound > work.policy_cap else ""))
        with _evaluation_progress(estimate, enabled=not as_json) as report:
            for solver in {id(ev): ev, id(self.optimum): self.optimum}.values():
                if solver is not None:
                    solver.deadline, solver.progress = until, report
            self.running = "optimum" if by_optimum else "policy"
            self.value = self.optimum.value() if pile and by_optimum else ev.value()
            report(ev, done=True)
            self.running = "optimum"
            if pile:
                self.best = self.optimum.value()
                self.states, self.policy_states = self.optimum.states, ev.states
            else:
                self.best = ev.optimal()
                self.states, self.policy_states = ev.states, ev.policy_states

    def _estimate_gap(self, engine, chosen, config, until, as_json: bool) -> None:
        """``--runs``: the optimum exactly, then the policy's gap from seeded runs by its regrets over it."""
        from opportune.policies.optimal import OutOfTime, optimal_solver
        from opportune.policies.regret import estimate_gap

        pile, work = self.chosen_bin == "pile", self.work
        if not pile:
            weights = config.weights if self.chosen_bin == "weighted" else None
            self.optimum = optimal_solver(engine, visible=config.visible, capacity=config.buffer_capacity,
                                          costs=config.costs, weights=weights, max_states=work.optimum_cap)
        if not as_json:
            out().print(f"states: {self.estimate.describe()} for the optimum "
                        f"({work.optimum_words(self.estimate.states)}); the policy's gap from {self.runs:,} runs")
        self.ev, self.policy_bound = None, 0
        self.optimum.deadline = until
        try:
            with _evaluation_progress(self.estimate, enabled=not as_json) as report:
                self.optimum.progress = report
                self.estimated = estimate_gap(self.optimum, chosen, runs=self.runs, seed=self.seed, pile=pile,
                                              deadline=until)
        except OutOfTime as exc:
            fail(f"the estimate of {self.plan.name}'s gap passed --time-limit {self.time_limit:g} s: {exc} "
                 f"({self.optimum.states:,} of the optimum's {self.estimate.describe()} states stored); raise the "
                 "limit, or give fewer --runs")
        self.best, self.value = self.estimated.optimum, self.estimated.optimum * (1 + self.estimated.gap)
        self.states, self.policy_states = self.optimum.states, 0


def _duration(seconds: float) -> str:
    """``'under a second'``, ``'40 s'``, ``'12 min'``, ``'3.5 h'``, ``'2.1e+05 years'``."""
    if seconds < 1:
        return "under a second"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 86400 * 365:
        return f"{seconds / 3600:.1f} h"
    years = seconds / (86400 * 365)
    return f"{years:,.0f} years" if years < 1e6 else f"{years:.1e} years"


def _how_far(ev, optimum, chosen_bin: str) -> str:
    """States done by the policy's programme and the optimum's, in words."""
    if ev is None:
        return "no states"
    if chosen_bin == "pile":
        done = [("the policy's", ev.states), ("the optimum's", optimum.states if optimum is not None else 0)]
    else:
        done = [("the policy's", ev.policy_states), ("the optimum's", ev.states)]
    return " and ".join(f"{n:,} of {who}" for who, n in done) + " states"


class _evaluation_progress:
    """A rich progress bar of states done / expected, on a terminal (standard output and error) and not under
    ``--json``; otherwise a no-op.  Used as ``with ... as report``; ``report(solver)`` every 64 new states,
    ``report(solver, done=True)`` when the policy's programme has finished (it reaches fewer states)."""

    def __init__(self, estimate, *, enabled: bool):
        self.estimate = estimate
        self.enabled = enabled and out().is_terminal and err().is_terminal
        self.bar = None
        self.tasks: dict[str, int] = {}

    def __enter__(self):
        if self.enabled:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("states"), TimeElapsedColumn(), console=err(), transient=True)
            self.bar.__enter__()
            total = max(1, self.estimate.states)
            self.tasks = {"policy": self.bar.add_task("policy ", total=total),
                          "optimum": self.bar.add_task("optimum", total=total)}
        return self.report

    def report(self, solver, done: bool = False) -> None:
        if self.bar is None:
            return
        from opportune.policies.evaluate import PolicyEvaluator

        if isinstance(solver, PolicyEvaluator):
            counts = {"policy": solver.policy_states, "optimum": solver.states}
        else:
            counts = {"policy" if solver.policy is not None else "optimum": solver.states}
        for name, n in counts.items():
            if done and name == "policy":
                self.bar.update(self.tasks[name], completed=n, total=max(1, n))
            else:
                self.bar.update(self.tasks[name], completed=n)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.__exit__(*exc)
        return False
