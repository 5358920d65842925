"""The multi-product study: N gearboxes at once from one bin, against N separate cells and one after another.

For N = 1 .. ``--max-products`` (default 4) copies of the gearbox (``example:gearbox``), each of the
three cells of :mod:`opportune.study.simulate_products` — N fixtures fed from one bin, N cells each with
its own bin, and one product after another from the one bin — is simulated with the paper's rule and
the default policy (``lookahead``; with a part kind needed on several fixtures it decides by its
base rule, ``slack``), in a uniform bin showing 2 parts, for each buffer size of ``--buffers``
(``none`` = unlimited).  Seeded: the same command prints the same numbers on any machine.

The table gives, per cell and policy, the mean time per product with its 95% interval (every
motion and shake costs 1, a look 0), the buffer moves and shakes per product, the buffer's peak
(mean over trials, and largest) and its mean occupancy (parts in the buffer at a look).

    python benchmarks/multi_product.py                                   # 1000 trials each, a few minutes
    python benchmarks/multi_product.py --trials 200 --max-products 3     # quicker
    python benchmarks/multi_product.py --plot docs/img/multi-product.png --compact   # the table in docs/products.md
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from opportune.datasets import example_path
from opportune.formats import load_plan
from opportune.study.simulate_products import (
    MODE_LABELS,
    MODES,
    ProductsConfig,
    copies,
    run_products,
)

POLICIES = ("paper", "lookahead")


def study(trials: int, max_products: int, buffers: list[int | None], seed: int) -> list[dict]:
    """Every row of the study: one per buffer size, N, cell and policy."""
    plan = load_plan(example_path("gearbox"))
    rows = []
    for capacity in buffers:
        for n in range(1, max_products + 1):
            t0 = time.perf_counter()
            config = ProductsConfig(copies(plan, n), policies=POLICIES, trials=trials, seed=seed,
                                    buffer_capacity=capacity)
            for row in run_products(config).summary()["rows"]:
                rows.append({"buffer": capacity, "n": n, **row})
            print(f"  buffer {'unlimited' if capacity is None else capacity}, N = {n}: "
                  f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return rows


def table(rows: list[dict], markdown: bool) -> str:
    head = ["buffer", "N", "cell", "policy", "time / product (95% CI)", "buffer moves / product",
            "shakes / product", "buffer peak (mean, max)", "buffer mean"]
    lines = []
    if markdown:
        lines += ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 4 + ["---:"] * 5) + "|"]
    else:
        lines.append("  ".join(head))
    for r in rows:
        t = r["time"]
        cells = ["unlimited" if r["buffer"] is None else str(r["buffer"]), str(r["n"]),
                 MODE_LABELS[r["mode"]].replace("N ", f"{r['n']} "), r["policy"],
                 f"{t['mean']:.2f} ({t['ci95'][0]:.2f} – {t['ci95'][1]:.2f})",
                 f"{r['buffer_moves']['mean']:.2f}", f"{r['shakes']['mean']:.2f}",
                 f"{r['buffer_peak']['mean']:.2f}, {r['buffer_max']}", f"{r['buffer_mean']['mean']:.2f}"]
        lines.append("| " + " | ".join(cells) + " |" if markdown else "  ".join(cells))
    return "\n".join(lines)


def compact(rows: list[dict]) -> str:
    """The table of docs/products.md (Markdown): per buffer size, N and cell, the time per product of both policies and
    the paper's rule's shakes and buffer use (N = 1 once: its three cells are the same run)."""
    head = ["buffer", "N", "cell", "time / product, paper (95% CI)", "time / product, lookahead",
            "shakes / product", "buffer max", "buffer mean"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 3 + ["---:"] * 5) + "|"]
    by = {(r["buffer"], r["n"], r["mode"], r["policy"]): r for r in rows}
    for (capacity, n, mode, policy), r in by.items():
        if policy != "paper" or (n == 1 and mode != "together"):
            continue
        la = by.get((capacity, n, mode, "lookahead"))
        t = r["time"]
        label = "1 fixture, 1 bin" if n == 1 else MODE_LABELS[mode].replace("N ", f"{n} ")
        lines.append("| " + " | ".join([
            "unlimited" if capacity is None else str(capacity), str(n), label,
            f"{t['mean']:.2f} ({t['ci95'][0]:.2f} – {t['ci95'][1]:.2f})",
            f"{la['time']['mean']:.2f}" if la else "", f"{r['shakes']['mean']:.2f}", str(r["buffer_max"]),
            f"{r['buffer_mean']['mean']:.2f}"]) + " |")
    return "\n".join(lines)


def plot(rows: list[dict], buffers: list[int | None], path: Path) -> None:
    """Time per product against N, one panel per buffer size: a line per cell, solid for the paper's
    rule and dashed for the default policy, with 95% intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(buffers), figsize=(5.2 * len(buffers), 4), sharey=True, squeeze=False)
    colours = {"together": "tab:blue", "independent": "tab:green", "serial": "tab:red"}
    for ax, capacity in zip(axes[0], buffers):
        for mode in MODES:
            for policy, style in zip(POLICIES, ("-", "--")):
                pts = [r for r in rows if r["buffer"] == capacity and r["mode"] == mode and r["policy"] == policy]
                ns = [r["n"] for r in pts]
                means = [r["time"]["mean"] for r in pts]
                err = [r["time"]["mean"] - r["time"]["ci95"][0] for r in pts]
                ax.errorbar(ns, means, yerr=err, color=colours[mode], linestyle=style, marker="o", capsize=3,
                            label=f"{MODE_LABELS[mode]} ({policy})")
        ax.set_title(f"buffer {'unlimited' if capacity is None else capacity}")
        ax.set_xlabel("products N")
        ax.set_xticks(sorted({r['n'] for r in rows}))
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean time per product (motions + shakes)")
    axes[0][-1].legend(fontsize=7, loc="upper left")
    fig.suptitle("Gearbox: N products at once from one bin vs N cells vs one after another")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1000, help="Trials per N, cell and policy")
    ap.add_argument("--max-products", type=int, default=4, help="N from 1 to this (at most 16)")
    ap.add_argument("--buffers", default="none,2", help="Buffer sizes, comma-separated ('none': unlimited)")
    ap.add_argument("--seed", type=int, default=0, help="Seed of the bins")
    ap.add_argument("--plot", type=Path, default=None, help="Write the plot here (PNG)")
    ap.add_argument("--markdown", action="store_true", help="Print the table in Markdown")
    ap.add_argument("--compact", action="store_true", help="Print the shorter table of docs/products.md (Markdown)")
    args = ap.parse_args(argv)
    buffers = [None if b.strip() in ("none", "") else int(b) for b in args.buffers.split(",")]
    t0 = time.perf_counter()
    rows = study(args.trials, args.max_products, buffers, args.seed)
    print(compact(rows) if args.compact else table(rows, args.markdown))
    print(f"\n{args.trials} trials per row, seed {args.seed}, {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if args.plot:
        plot(rows, buffers, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)


if __name__ == "__main__":
    main()
