"""Per-plan work in the service, through the in-process app: run start, look latency, reads, memory per plan.

For each plan: upload it, start two runs (the first warms the plan up: at most 1 s in the request, the
rest in the background; the second finds it built), drive the second with looks of two parts drawn from
its bin (every action succeeding) and time each look, then one GET /runs/{id} and one trace.  Memory:
the server's RSS growth and the bytes the plan book accounts.

    .venv/bin/python benchmarks/bench_service_plans.py gen-n1000-os0.6.alb free:10000 --looks 40
    .venv/bin/python benchmarks/bench_service_plans.py --memory 5 --cap-mb 600   # five 10,000-unit plans
    .venv/bin/python benchmarks/bench_service_plans.py salbp:ARC111 --before 20   # looks after 20 whole runs

``--optimum CAPACITY`` instead times the look-ahead's optimum prepared in the background for runs with that
many buffer locations: looks of seeded runs while it is under way (their latency, and who decided), the
seconds until it is ready, and looks after it (the optimum deciding).

    .venv/bin/python benchmarks/bench_service_plans.py salbp:KILBRID --optimum 1 --pause 0.5

``--before N`` drives N whole runs of each plan to completion first (one engine, as a long-running cell
uses it) and times the looks of the run after them.

Plans: files or shipped names as `opportune` reads them (``benchmarks/gen_precedence.py`` makes
``.alb`` graphs), or ``free:N`` for N unconstrained parts.  Wall times on whatever else the machine runs.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time


def rss() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) * 1024
    return 0


def plan_doc(name: str) -> dict:
    if name.startswith("free:"):
        n = int(name[5:])
        return {"name": f"free-{n}", "parts": [f"p{i}" for i in range(n)]}
    from opportune import load_plan

    return load_plan(name).to_dict()


class App:
    def __init__(self, **settings):
        from fastapi.testclient import TestClient

        from opportune.service.app import create_app
        from opportune.service.auth import create_token
        from opportune.service.config import Settings
        from opportune.service.storage import Store

        url = f"sqlite:///{tempfile.mkdtemp()}/bench.db"
        store = Store(url)
        self.headers = {"Authorization": f"Bearer {create_token(store, cell='c')[1]}"}
        self.app = create_app(Settings(db_url=url, max_body=1 << 25, **settings), store)
        self.book = self.app.state.manager.book
        self.client = TestClient(self.app).__enter__()
        self.keys = 0

    def post(self, path: str, body: dict):
        self.keys += 1
        t = time.perf_counter()
        r = self.client.post(path, json=body, headers={**self.headers, "Idempotency-Key": f"k{self.keys}"})
        return r, time.perf_counter() - t

    def get(self, path: str):
        t = time.perf_counter()
        r = self.client.get(path, headers=self.headers)
        return r, time.perf_counter() - t


def drive(app: App, run: dict, looks: int, seed: int) -> list[float]:
    rng = random.Random(seed)
    times = []
    for _ in range(looks):
        in_bin = [p for p, n in run["state"]["in_bin"].items() for _ in range(n)]
        if not in_bin:
            break
        r, dt = app.post(f"/runs/{run['id']}/looks", {"visible": rng.sample(in_bin, min(2, len(in_bin)))})
        if r.status_code != 200:
            print("  look:", r.status_code, r.text[:200])
            break
        times.append(dt)
        r, _ = app.post(f"/runs/{run['id']}/outcomes", {"outcome": "success"})
        run = r.json()["run"]
    return times


def ms(xs: list[float], q: float) -> str:
    xs = sorted(xs)
    return f"{1e3 * xs[min(len(xs) - 1, int(q * len(xs)))]:.0f}" if xs else "-"


def bench_plans(names: list[str], looks: int, before: int = 0) -> None:
    app = App()
    print("| plan | upload s | first POST /runs s | second POST /runs s | looks | p50 ms | p95 ms | max ms "
          "| GET run s | trace s | RSS +MB | accounted MB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        doc = plan_doc(name)
        r0 = rss()
        r, up = app.post("/plans", doc)
        pid = r.json()["id"]
        _, first = app.post("/runs", {"plan": pid})
        for i in range(before):     # long use of the plan's engine first
            drive(app, app.post("/runs", {"plan": pid})[0].json(), 10**9, 100 + i)
        r, second = app.post("/runs", {"plan": pid})
        run = r.json()
        times = drive(app, run, looks, 1)
        _, view = app.get(f"/runs/{run['id']}")
        _, trace = app.get(f"/runs/{run['id']}/trace")
        loaded = {p.id: p for p in app.book.loaded()}.get(pid)
        print(f"| {doc['name']} | {up:.2f} | {first:.2f} | {second:.2f} | {len(times)} | {ms(times, .5)} | "
              f"{ms(times, .95)} | {ms(times, 1)} | {view:.2f} | {trace:.2f} | {(rss() - r0) >> 20} | "
              f"{(loaded.nbytes >> 20) if loaded else 'evicted'} |")


def drive_rules(app: App, pid: str, capacity: int, seed: int, pause: float = 0.0) -> tuple[list[float], int, int]:
    """One whole seeded run with ``capacity`` buffer locations, ``pause`` seconds between an outcome and the next
    look (the robot's motion): (look seconds, looks the optimum decided, looks)."""
    from opportune.policies.lookahead import Lookahead

    rng = random.Random(seed)
    run = app.post("/runs", {"plan": pid, "buffer_capacity": capacity})[0].json()
    times, optimum = [], 0
    while run["status"] != "complete":
        in_bin = [p for p, n in run["state"]["in_bin"].items() for _ in range(n)]
        r, dt = app.post(f"/runs/{run['id']}/looks", {"visible": rng.sample(in_bin, min(2, len(in_bin)))})
        if r.status_code != 200:
            print("  look:", r.status_code, r.text[:200])
            break
        times.append(dt)
        optimum += r.json()["decision"]["rule"] == Lookahead.OPTIMAL_RULE
        run = app.post(f"/runs/{run['id']}/outcomes", {"outcome": "success"})[0].json()["run"]
        time.sleep(pause)
    return times, optimum, len(times)


def bench_optimum(names: list[str], capacity: int, cap_mb: int | None, pause: float) -> None:
    app = App(memory_cap=cap_mb << 20 if cap_mb else None)
    print("| plan | buffer | runs while under way | looks | by the optimum | p50 ms | p99 ms | max ms | ready after s "
          "| CPU s | state | looks after | by the optimum | p50 ms | p99 ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        r, _ = app.post("/plans", plan_doc(name))
        pid = r.json()["id"]
        t0, c0 = time.perf_counter(), time.process_time()
        app.post("/runs", {"plan": pid, "buffer_capacity": capacity})
        loaded = {p.id: p for p in app.book.loaded()}[pid]
        during, by, runs = [], 0, 0
        while loaded.optima.get(("lookahead", capacity)) in ("waiting", "under way"):
            times, opt, _ = drive_rules(app, pid, capacity, runs, pause)
            during, by, runs = during + times, by + opt, runs + 1
        ready, cpu = time.perf_counter() - t0, time.process_time() - c0
        after, by_after = [], 0
        for i in range(3):
            times, opt, _ = drive_rules(app, pid, capacity, 1000 + i)
            after, by_after = after + times, by_after + opt
        print(f"| {name} | {capacity} | {runs} | {len(during)} | {by} | {ms(during, .5)} | {ms(during, .99)} | "
              f"{ms(during, 1)} | {ready:.1f} | {cpu:.1f} | {loaded.optima[('lookahead', capacity)]} | {len(after)} | "
              f"{by_after} | {ms(after, .5)} | {ms(after, .99)} |")


def bench_memory(plans: int, cap_mb: int | None) -> None:
    app = App(memory_cap=cap_mb << 20 if cap_mb else None)
    print(f"cap {app.book.memory_cap >> 20} MB, a plan's share {app.book.share >> 20} MB")
    r0 = rss()
    for i in range(plans):
        r, _ = app.post("/plans", {"name": f"free-{i}", "parts": [f"q{i}_{j}" for j in range(10_000)]})
        run, _ = app.post("/runs", {"plan": r.json()["id"]})
        drive(app, run.json(), 5, i)
        time.sleep(0.6)         # past the measurement interval: the read below measures the plan
        app.get(f"/runs/{run.json()['id']}")
        print(f"plan {i + 1}: RSS +{(rss() - r0) >> 20} MB, accounted {app.book.nbytes() >> 20} MB, "
              f"{len(app.book.loaded())} loaded, {app.book.evictions} evicted")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("plans", nargs="*", help="plan files or names, or free:N")
    ap.add_argument("--looks", type=int, default=40, help="looks per run (default 40)")
    ap.add_argument("--before", type=int, default=0, metavar="N",
                    help="whole runs of each plan driven to completion before the timed one (default 0)")
    ap.add_argument("--memory", type=int, metavar="N", help="instead: N distinct 10,000-unit plans, one after another")
    ap.add_argument("--cap-mb", type=int, help="with --memory or --optimum: the memory cap in MB (default: a quarter "
                                               "of the memory)")
    ap.add_argument("--pause", type=float, default=0.0, help="with --optimum: seconds between an outcome and the "
                                                             "next look while it is under way (default 0)")
    ap.add_argument("--optimum", type=int, metavar="CAPACITY",
                    help="instead: the look-ahead's optimum prepared in the background for runs of CAPACITY locations")
    args = ap.parse_args(argv)
    print(f"# {os.uname().machine}, {os.cpu_count()} cores, Python {sys.version.split()[0]}, "
          f"load average {os.getloadavg()[0]:.1f}")
    if args.memory:
        bench_memory(args.memory, args.cap_mb)
    elif args.optimum is not None:
        bench_optimum(args.plans or ["salbp:KILBRID"], args.optimum, args.cap_mb, args.pause)
    else:
        bench_plans(args.plans or ["free:10000"], args.looks, args.before)
    return 0


if __name__ == "__main__":
    sys.exit(main())
