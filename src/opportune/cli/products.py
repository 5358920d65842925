"""``simulate PLAN --products N``: N copies of a plan built on N fixtures from one bin, against N separate
cells and one product after another.

The study is :mod:`opportune.study.simulate_products`'s; what is here is option plumbing and the table.

Imports: typer only; the study loads when the command runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from opportune.cli.common import fail, load_or_exit, out, policy_names, progress_bar

_NOT_WITH_PRODUCTS = ("from_results", "workers", "dask", "out_dir", "training_runs", "optimal_states",
                      "count_time_limit")


def simulate_products(ctx: typer.Context, plan_file: Optional[Path], products: int, *, strategies, trials, seed,
                      bin_model, visible, buffer_capacity, as_json, motion_cost, shake_cost, look_cost,
                      decision_budget) -> None:
    """``simulate PLAN --products N``: N fixtures from one bin, against N cells and one product after another."""
    given = [name for name in _NOT_WITH_PRODUCTS
             if getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"]
    if given:
        flag = {"from_results": "--from", "out_dir": "--out"}.get(given[0], "--" + given[0].replace("_", "-"))
        fail(f"{flag} does not apply with --products (the multi-product study runs in this process and prints "
             "its table, or --json)", 2, as_json=as_json)
    if plan_file is None:
        fail("give a plan file to build several products of", 2, as_json=as_json)
    from opportune.planning.products import ProductsError
    from opportune.study.simulate_products import ProductsConfig, copies, run_products
    from opportune.worlds import TimeModel

    plan = load_or_exit(plan_file, json_errors=as_json)
    sim = plan.simulation
    policies = tuple(policy_names(s.strip() for s in (strategies or "paper,lookahead").split(",") if s.strip()))
    if not policies:
        fail("--strategies is empty: name at least one policy, e.g. paper,lookahead", 2, as_json=as_json)
    try:
        config = ProductsConfig(
            copies(plan, products), policies=policies, trials=trials, seed=seed,
            bin=bin_model or sim.get("bin", "uniform"), visible=visible or sim.get("visible", 2),
            buffer_capacity=buffer_capacity if buffer_capacity is not None else sim.get("buffer_capacity"),
            costs=TimeModel.from_plan(plan, motion=motion_cost, shake=shake_cost, look=look_cost),
            decision_budget=decision_budget).validate()
        progress = progress_bar()
        with progress:
            task = progress.add_task("simulating", total=trials * len(config.modes) * len(policies))
            result = run_products(config, progress=lambda _mode, _policy, n: progress.advance(task, n))
    except (ProductsError, ValueError) as exc:
        fail(str(exc), as_json=as_json)
    doc = result.summary()
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    _print_products(plan.name, products, config, doc)


def _print_products(name: str, products: int, config, doc: dict) -> None:
    """The multi-product study's table (time, buffer moves and shakes per product, in each cell) and its note."""
    from rich.table import Table

    from opportune.study.simulate_products import MODE_LABELS

    cap = "unlimited" if config.buffer_capacity is None else config.buffer_capacity
    table = Table(title=f"{name} ×{products}: {config.bin} bin, {config.visible} visible, buffer {cap}, "
                        f"{config.trials:,} trials, seed {config.seed}; time, buffer moves and shakes per product")
    for i, col in enumerate(("cell", "policy", "time ± 95%", "buffer moves", "shakes", "buffer peak (mean, max)",
                             "buffer mean", "complete")):
        table.add_column(col, justify="left" if i < 2 else "right")
    for row in doc["rows"]:
        t = row["time"]
        table.add_row(MODE_LABELS[row["mode"]].replace("N ", f"{products} "), row["policy"],
                      f"{t['mean']:.2f} ± {t['mean'] - t['ci95'][0]:.2f}",
                      f"{row['buffer_moves']['mean']:.2f}", f"{row['shakes']['mean']:.2f}",
                      f"{row['buffer_peak']['mean']:.2f}, {row['buffer_max']}", f"{row['buffer_mean']['mean']:.2f}",
                      f"{row['complete']}/{row['trials']}")
    out().print(table)
    modelled = [p for p in config.policies if p in ("lookahead", "rollout")]
    if products > 1 and modelled:
        out().print(f"note: with a part kind needed on several fixtures, {' and '.join(modelled)} decide"
                    f"{'s' if len(modelled) == 1 else ''} by the base rule (slack): its model of the bin is "
                    "one product's parts")
