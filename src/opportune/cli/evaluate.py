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
from opportune.limits import MAX_BUFFER

# The programmes' speed, measured in CPU time on a 2-core machine: the optimum's states (as estimated
# before the start) per second of the whole evaluation (the policy's programme and the optimum's), about
# 500-1,000/s in a Markov bin on plans of 11-21 parts (a state costs a look-up per look, ~r²/2 looks with r
# parts left) and 4,000-10,000/s in the pile (whose windows are stored several at once).  They set the
# default of --max-states (about a minute) and the time a refusal quotes.
EVALUATE_STATES_PER_SECOND = {"uniform": 500, "weighted": 500, "pile": 4_000}
EVALUATE_MAX_STATES = 30_000


def evaluate(
    plan_file: Path = PLAN_ARG,
    policy: str = typer.Option("lookahead", "--policy",
                               help="The policy to evaluate: lookahead (the default policy), paper "
                                    "(the paper's rule), bin-first, slack, rollout, buffer, shake or quantify"),
    bin_model: Optional[str] = typer.Option(None, "--bin", help="uniform, weighted or pile (default: plan, else uniform)"),
    visible: Optional[int] = typer.Option(None, "--visible", min=1, help="Parts seen per look (default: plan, else 2)"),
    buffer_capacity: Optional[int] = typer.Option(None, "--buffer-capacity", min=0, max=MAX_BUFFER,
                                                  help="Buffer locations (default: plan, else unlimited)"),
    max_states: int = typer.Option(
        EVALUATE_MAX_STATES, "--max-states", min=1,
        help=f"Most states of the dynamic programme (default {EVALUATE_MAX_STATES:,}: about a minute at the "
             f"~{EVALUATE_STATES_PER_SECOND['uniform']:,} states/s measured on a 2-core machine (seconds on plans of "
             "10 parts, up to two minutes of CPU on plans of 45; the pile bin is ~8 times faster), and at most "
             f"about {2 * EVALUATE_MAX_STATES * 1_000 // 10**6 + 30} MB).  The states a plan needs are counted or "
             "estimated before the programme starts, and a plan over the limit is refused at once"),
    time_limit: Optional[float] = typer.Option(None, "--time-limit", min=0.0,
                                               help="Stop the programme after this many seconds and say how far it "
                                                    "got (default: none; --max-states bounds the work)"),
    without_optimum: bool = typer.Option(False, "--without-optimum",
                                         help="The default policy (lookahead) with its exact optimum switched off: "
                                              "it decides by its fallback (the exact optimum of a frontier window of "
                                              "the plan, the rest lumped, in its bin), measured against the optimum"),
    as_json: bool = json_option(),
):
    """Exact expected cost of a policy and of the optimum (a dynamic programme, no Monte Carlo error).

    The states the programme needs are counted (or estimated, on large plans) first: a plan over --max-states is
    refused before any work, with the figure.  On a terminal a progress bar shows states done / expected."""
    from opportune.engine import OrderEngine

    plan = load_or_exit(plan_file, json_errors=as_json, ways=True)    # a policy that does not take it: refused below
    chosen_bin = bin_model or plan.simulation.get("bin", "uniform")
    policy = _evaluated_policy(policy, chosen_bin, without_optimum, as_json)
    config = _evaluation_config(plan, policy, chosen_bin, visible, buffer_capacity, max_states)
    engine = OrderEngine(plan)
    run = _Run(plan, policy, chosen_bin, max_states, time_limit, _estimate(engine, config, chosen_bin, max_states))
    run.solve(engine, config, without_optimum, as_json)
    doc = {"plan": plan.name, "policy": policy, "bin": chosen_bin, "visible": config.visible,
           "buffer_capacity": config.buffer_capacity, "expected_time": run.value, "optimal": run.best,
           "ratio": run.value / run.best if run.best else None, "states": run.states,
           "policy_states": run.policy_states, "estimated_states": run.estimate.states,
           "estimate_exact": run.estimate.exact, "estimated_policy_states": run.policy_bound,
           "buffer_order_kept": run.ordered, "policy_by_optimum": bool(getattr(run.ev, "by_optimum", False)),
           "without_optimum": without_optimum}
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
    value, best = run.value, run.best
    out().print(f"{plan.name}: {chosen_bin} bin, {config.visible} visible, buffer {cap}")
    out().print(f"  {policy}{' (its exact optimum switched off)' * without_optimum}: expected time {value:.4f}")
    out().print(f"  optimum: expected time {best:.4f}")
    reached = ("the policy decides by the optimum's values, so its value is the optimum's"
               if doc["policy_by_optimum"] else f"{run.policy_states:,} reached by the policy")
    out().print(f"  ratio {value / best:.5f} ({100 * (value / best - 1):+.2f}%); "
                f"{run.states:,} states for the optimum, {reached}")


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
                           costs=TimeModel.from_plan(plan), optimal_states=max_states).validate()
    except (StudyError, ValueError) as exc:
        fail(str(exc))


def _simulate_hint(chosen_bin: str) -> str:
    """The command that estimates what the exact evaluation cannot reach."""
    return f"`opportune simulate{' --bin pile' if chosen_bin == 'pile' else ''}`"


def _estimate(engine, config, chosen_bin: str, max_states: int):
    """The states the evaluation needs, counted or estimated before any (a few seconds at most, and far cheaper
    per state than the programme); exit with the figure when they are out of reach or over --max-states."""
    from opportune.policies.optimal import LOOK_CACHE_LOOKS
    from opportune.policies.states import BYTES_PER_STATE, big, estimate_states

    plan = config.plan
    estimate = estimate_states(engine, visible=config.visible, capacity=config.buffer_capacity,
                               pile=chosen_bin == "pile", stop_above=max_states, time_limit=3.0)
    if estimate.looks > LOOK_CACHE_LOOKS:
        fail(f"the exact evaluation of {plan.name} would weigh {estimate.looks:,} distinct looks at every state "
             f"({plan.n_units:,} parts, {config.visible} visible), more than the {LOOK_CACHE_LOOKS:,} the programme "
             f"keeps: it is out of reach whatever --max-states; estimate it by Monte Carlo with "
             f"{_simulate_hint(chosen_bin)}")
    if estimate.over(max_states):
        figure = max(estimate.states, estimate.low)
        rate = EVALUATE_STATES_PER_SECOND[chosen_bin]
        fail(f"the exact evaluation of {plan.name} needs {estimate.describe()} states, more than --max-states "
             f"{max_states:,} (at ~{rate:,} states/s that is {_duration(figure / rate)}, and about "
             f"{big(2 * figure * BYTES_PER_STATE // 10**6)} MB): raise --max-states, reduce --buffer-capacity or "
             f"--visible, or estimate it by Monte Carlo with {_simulate_hint(chosen_bin)}")
    return estimate


class _Run:
    """One evaluation: its request, its programmes (the policy's and the optimum's; kept as they are made, so
    that a stop can say how far they got) and what they found.  (A plain class: ``dataclasses`` is not
    loaded at the command line's start-up for this one.)"""

    def __init__(self, plan, policy: str, chosen_bin: str, max_states: int, time_limit: Optional[float], estimate):
        self.plan, self.policy, self.chosen_bin, self.estimate = plan, policy, chosen_bin, estimate
        self.max_states, self.time_limit = max_states, time_limit
        self.ev = self.optimum = None
        self.policy_bound, self.ordered = 0, False
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
            why = (f"passed --time-limit {self.time_limit:g} s" if isinstance(exc, OutOfTime)
                   else f"needed more than --max-states {self.max_states:,} states")
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

    def _programmes(self, engine, chosen, config, until, as_json: bool) -> None:
        """Make the policy's programme and the optimum's, say how many states they may reach, and run them."""
        from opportune.policies.evaluate import PolicyEvaluator
        from opportune.policies.states import big

        estimate, pile = self.estimate, self.chosen_bin == "pile"
        settings = dict(visible=config.visible, capacity=config.buffer_capacity, costs=config.costs,
                        max_states=self.max_states)
        if pile:
            from opportune.policies.pile import PileSolver, pile_solver

            # the optimum compiled where the core is built (the same values): the policy's programme in Python
            self.ev, self.optimum = PileSolver(engine, chosen, **settings), pile_solver(engine, **settings)
            if estimate.exact:
                self.optimum.reserve(estimate.states)    # a compiled table sized at once: it never doubles
        else:
            weights = config.weights if self.chosen_bin == "weighted" else None
            self.ev = PolicyEvaluator(engine, chosen, weights=weights, **settings)
        ev = self.ev
        ev.deadline = until         # finding where the buffer's order decides counts options: within it too
        # a policy deciding by the optimum is worth the optimum: none of its own states are evaluated
        by_optimum = not pile and ev.takes_optimum()
        self.policy_bound, self.ordered = (0, False) if by_optimum else (ev.states_bound(estimate.states), ev.ordered)
        kept = " (its buffer kept in the order of buffering)" if self.ordered else ""
        if not as_json and by_optimum:
            out().print(f"states: {estimate.describe()} for the optimum; none for the policy (it decides by the "
                        "optimum's values: its value is the optimum's)")
        elif not as_json:
            # a bound, not a count: the policy reaches a part of these states (it stops at --max-states if not)
            out().print(f"states: {estimate.describe()} for the optimum, at most {big(self.policy_bound)} for the "
                        f"policy{kept}" + (f"; it stops if it passes --max-states {self.max_states:,}"
                                           if self.policy_bound > self.max_states else ""))
        with _evaluation_progress(estimate, enabled=not as_json) as report:
            for solver in {id(ev): ev, id(self.optimum): self.optimum}.values():
                if solver is not None:
                    solver.deadline, solver.progress = until, report
            if hasattr(chosen, "deadline"):    # a policy with a programme of its own (the look-ahead) stops too
                chosen.deadline = until
            self.value = ev.value()
            report(ev, done=True)
            if pile:
                self.best = self.optimum.value()
                self.states, self.policy_states = self.optimum.states, ev.states
            else:
                self.best = ev.optimal()
                self.states, self.policy_states = ev.states, ev.policy_states


def _duration(seconds: float) -> str:
    """``'40 s'``, ``'12 min'``, ``'3.5 h'``, ``'2.1e+05 years'``."""
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
