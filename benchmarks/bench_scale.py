"""Every promise at every size: count, the service and evaluate from 10 to 10,000 parts.

For each plan (the gearbox, KILBRID, ARC111, generated assembly graphs of 300 to 10,000 tasks at
order strengths 0.2, 0.6 and 0.9, 10,000 free parts, and one part of 10,000 units) it measures:

* **count** — ``opportune count PLAN --time-limit 5 --json`` in a fresh process: wall and CPU
  seconds, and whether an answer came back (exact, or an estimate with its interval);
* **service** — one ``opportune serve`` process on loopback shared by every row, as a cell
  controller's is: the plan's upload, the first ``POST /runs`` and a second one, then the look
  latency (p50 / p95 / max, each look timed by the cell) over the first ``--looks`` looks of a
  fresh run, and again over the last ``--looks`` looks after ``--cell-hours`` of simulated cell
  time on the same plan (``--seconds-per-action`` of cell time per install or buffer), and the
  server's resident memory added by the plan (VmRSS before the upload and after its row);
* **evaluate** — ``opportune evaluate PLAN`` with its defaults: seconds until it answers or refuses.

The cell's looks are 1–3 units drawn from what is still in the bin (seeded), every outcome a
success.  Loopback only; the server and the cell share the machine, so latencies are a ceiling of
what the engine alone needs.  Prints a Markdown table (``--out FILE`` writes it too).

    .venv/bin/python benchmarks/bench_scale.py                       # every row (about an hour)
    .venv/bin/python benchmarks/bench_scale.py --rows gearbox,gen-1000-0.6 --cell-hours 0.1
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from load_service import percentile  # noqa: E402  (benchmarks/ is on the path)

SIZES = (300, 1000, 3000, 10_000)
STRENGTHS = (0.2, 0.6, 0.9)


def rss_mb(pid: int) -> float:
    """Resident memory of a process in MB (Linux /proc)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def server_memory(pid: int, start: float, cap_mb: int | None = None) -> str:
    """The server's resident memory now and at its peak, against its footprint at ``start`` (MB) plus its
    memory cap (``cap_mb``; None: the default, a quarter of the machine's memory, as the server computes
    it), as a sentence."""
    from opportune.engine.memory import memory_total

    peak = float("nan")
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                peak = int(line.split()[1]) / 1024
    except OSError:
        pass
    cap = memory_total() // 4 / 2**20 if cap_mb is None else cap_mb
    which = "the default: a quarter of the machine's memory" if cap_mb is None else "`serve --memory-cap`"
    now = rss_mb(pid)
    verdict = "under" if peak - start <= cap else "over"
    return (f"Server memory after every row: {now:,.0f} MB resident, {peak:,.0f} MB at its peak, {start:,.0f} MB at "
            f"start; the peak is {verdict} the start plus the memory cap of {cap:,.0f} MB ({which}). The cap is kept "
            f"between requests on the bytes the plans' engines account and on the process's resident memory (past "
            f"85% of it the plans' memos are shrunk; over it, least recently used plans are evicted).")


def make_plans(tmp: Path, names: set[str] | None) -> list[tuple[str, str]]:
    """``(row name, plan path or spec)`` for every row asked for (all when ``names`` is None)."""
    rows: list[tuple[str, str]] = [("gearbox", "example:gearbox"), ("KILBRID", "salbp:KILBRID"),
                                   ("ARC111", "salbp:ARC111")]
    for n in SIZES:
        for os_ in STRENGTHS:
            rows.append((f"gen-{n}-{os_}", f"gen:{n}:{os_}"))
    rows += [("free-10000", "free"), ("unit-10000", "unit")]
    out = []
    for name, spec in rows:
        if names is not None and name not in names:
            continue
        if spec.startswith("gen:"):
            from gen_precedence import file_name, generate
            from opportune.formats.alb import graph_text

            _, n, os_ = spec.split(":")
            path = tmp / file_name(int(n), float(os_))
            if not path.exists():
                arcs, times = generate(int(n), float(os_), "mixed", 1)
                path.write_text(graph_text(times, arcs))
            spec = str(path)
        elif spec == "free":
            path = tmp / "free-10000.yaml"
            path.write_text("name: free-10000\nparts: [" + ", ".join(f"p{i}" for i in range(10_000)) + "]\n")
            spec = str(path)
        elif spec == "unit":
            path = tmp / "unit-10000.yaml"
            path.write_text("name: unit-10000\nparts:\n  - base\n  - {id: bolt, quantity: 9998}\n  - cover\n"
                            "requires:\n  bolt: [base]\n  cover: [bolt]\n")
            spec = str(path)
        out.append((name, spec))
    return out


def timed_command(args: list[str], timeout: float) -> tuple[float, float, int | None, str]:
    """``(wall s, CPU s, exit code or None if killed at the timeout, standard output)``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        p = subprocess.run(args, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
        code, out = p.returncode, p.stdout
    except subprocess.TimeoutExpired as exc:
        code, out = None, exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, code, out


def measure_count(spec: str, limit: float) -> dict:
    wall, cpu, code, out = timed_command([sys.executable, "-m", "opportune.cli", "count", spec,
                                          "--time-limit", str(limit), "--json"], timeout=max(60.0, 6 * limit))
    row = {"count_wall": wall, "count_cpu": cpu, "count_answer": "none"}
    try:
        doc = json.loads(out)
    except ValueError:
        doc = {}
    if code is None:
        row["count_answer"] = "killed"
    elif doc.get("exact"):
        row["count_answer"] = "exact"
    elif doc.get("log10") is not None:
        rel = doc.get("rel_error")
        row["count_answer"] = f"±{100 * rel:.0f}%" if rel is not None and rel < 1 else "log interval"
    return row


def measure_evaluate(spec: str, timeout: float) -> dict:
    wall, cpu, code, _ = timed_command([sys.executable, "-m", "opportune.cli", "evaluate", spec], timeout=timeout)
    verdict = "killed" if code is None else ("answered" if code == 0 else "refused")
    return {"evaluate_wall": wall, "evaluate_cpu": cpu, "evaluate": verdict}


def drive(client, run: dict, rng: random.Random, looks: int | None, lat: list[float]) -> tuple[int, bool]:
    """Look and report success until the run is done or ``looks`` looks were timed; returns
    ``(actions taken, finished)``."""
    rid = run["id"]
    in_bin = run["state"]["in_bin"]
    actions = 0
    while looks is None or len(lat) < looks:
        units = [p for p, n in in_bin.items() for _ in range(n)]
        # an empty bin: the cell looks at nothing, and the buffer's parts go in
        visible = rng.sample(units, min(len(units), rng.randint(1, 3))) if units else []
        t0 = time.perf_counter()
        r = client.post(f"/runs/{rid}/looks", {"visible": visible})
        lat.append(time.perf_counter() - t0)
        if r.status_code != 200:
            raise RuntimeError(f"look answered {r.status_code}: {r.text[:300]}")
        if r.json()["action"]["kind"] == "done":
            return actions, True
        r = client.post(f"/runs/{rid}/outcomes", {"outcome": "success"})
        if r.status_code != 200:
            raise RuntimeError(f"outcome answered {r.status_code}: {r.text[:300]}")
        body = r.json()
        in_bin = body["run"]["state"]["in_bin"]
        actions += 1
        if body["run"].get("status") == "complete" or body["run"].get("finished"):
            return actions, True
    return actions, False


def measure_service(svc, client, name: str, spec: str, args, rng: random.Random) -> dict:
    from opportune.formats.loader import load_plan

    pid = svc.proc.pid
    rss0 = rss_mb(pid)
    # every plan goes up as JSON, as the loader read it (the service takes YAML and JSON documents)
    body = json.dumps(load_plan(spec).to_dict()).encode()
    headers, params = {"Content-Type": "application/json"}, {"filename": f"{name}.json"}
    t0 = time.perf_counter()
    r = client.post("/plans", content=body, headers=headers, params=params)
    upload = time.perf_counter() - t0
    if r.status_code not in (200, 201):
        return {"service": f"upload {r.status_code}: {r.json().get('error', {}).get('message', '')[:80]}",
                "upload": upload}
    plan_id = r.json()["id"]
    starts = []
    runs = []
    for _ in range(2):
        t0 = time.perf_counter()
        r = client.post("/runs", {"plan": plan_id})
        starts.append(time.perf_counter() - t0)
        if r.status_code != 201:
            return {"service": f"run {r.status_code}", "upload": upload, "start1": starts[0]}
        runs.append(r.json())
    fresh: list[float] = []
    drive(client, runs[0], rng, args.looks, fresh)
    # simulated cell time on the same plan (its engine shared by every run): runs one after another
    actions_wanted = int(args.cell_hours * 3600 / args.seconds_per_action)
    done_actions, late = 0, []
    run = runs[1]
    while done_actions < actions_wanted:
        window: list[float] = []
        a, finished = drive(client, run, rng, min(actions_wanted - done_actions, 10**9), window)
        done_actions += max(a, 1)
        late = (late + window)[-args.looks:]
        if finished and done_actions < actions_wanted:
            r = client.post("/runs", {"plan": plan_id})
            run = r.json()
    budget = runs[0].get("decision_budget") or args.budget
    return {"upload": upload, "start1": starts[0], "start2": starts[1], "budget": budget,
            "fresh": fresh, "late": late, "rss_added": rss_mb(pid) - rss0, "cell_actions": done_actions}


def fmt_lat(xs: list[float]) -> str:
    if not xs:
        return "—"
    return f"{1000 * statistics.median(xs):.0f} / {1000 * percentile(xs, 95):.0f} / {1000 * max(xs):.0f}"


def markdown(rows: list[dict], args) -> str:
    head = ("| plan | count s (CPU s) | count answer | run start s, first / next | look ms p50/p95/max, fresh "
            f"| after {args.cell_hours:g} h of cell time | server MB added | evaluate s |")
    lines = [head, "|---|---:|---|---:|---:|---:|---:|---|"]
    for r in rows:
        count = f"{r['count_wall']:.1f} ({r['count_cpu']:.1f})" if "count_wall" in r else "—"
        if "start1" in r and "start2" in r:
            start = f"{r['start1']:.2f} / {r['start2']:.2f}"
        else:
            start = r.get("service", "—")
        ev = f"{r['evaluate_wall']:.1f} ({r['evaluate']})" if "evaluate_wall" in r else "—"
        mem = f"{r['rss_added']:.0f}" if "rss_added" in r else "—"
        lines.append(f"| {r['name']} | {count} | {r.get('count_answer', '—')} | {start} | {fmt_lat(r.get('fresh', []))} "
                     f"| {fmt_lat(r.get('late', []))} | {mem} | {ev} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", help="comma-separated row names (default: all), e.g. gearbox,gen-1000-0.6,free-10000")
    ap.add_argument("--time-limit", type=float, default=5.0, help="count's --time-limit, seconds")
    ap.add_argument("--looks", type=int, default=200, help="looks timed per window")
    ap.add_argument("--cell-hours", type=float, default=2.0, help="simulated cell time before the second window")
    ap.add_argument("--seconds-per-action", type=float, default=3.0, help="cell seconds per install or buffer")
    ap.add_argument("--budget", type=float, default=0.05, help="the decision budget, if the run does not say")
    ap.add_argument("--evaluate-timeout", type=float, default=180.0, help="seconds before evaluate is killed")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: count, service, evaluate")
    ap.add_argument("--memory-cap", type=int, help="the server's --memory-cap in MB (default: its own default)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", type=Path, help="where generated plans are kept (default: opportune-scale in the temp dir)")
    ap.add_argument("--out", type=Path, help="also write the Markdown table here")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    skip = set(filter(None, args.skip.split(",")))
    # generated graphs are kept between runs (a 10,000-task one takes a minute or two to generate)
    tmp = args.work or Path(tempfile.gettempdir()) / "opportune-scale"
    tmp.mkdir(parents=True, exist_ok=True)
    plans = make_plans(tmp, set(args.rows.split(",")) if args.rows else None)
    rows = []
    svc = client = None
    if "service" not in skip:
        from opportune.service.testing import Client, ServiceProcess

        run_dir = Path(tempfile.mkdtemp(prefix="run-", dir=tmp))
        extra = ("--no-access-log",) + (("--memory-cap", str(args.memory_cap)) if args.memory_cap else ())
        svc = ServiceProcess(run_dir / "scale.db", extra_args=extra, log=run_dir / "server.log").start(60)
        client = Client(svc.url, svc.token(cell="scale"), timeout=600)
        rss_start = rss_mb(svc.proc.pid)
    load0 = os.getloadavg()[0]
    try:
        for name, spec in plans:
            row = {"name": name}
            if "count" not in skip:
                row.update(measure_count(spec, args.time_limit))
            if svc is not None:
                try:
                    row.update(measure_service(svc, client, name, spec, args, random.Random(args.seed)))
                except Exception as exc:      # one row's failure is reported in its row; the table goes on
                    row["service"] = f"error: {exc}"[:120]
            if "evaluate" not in skip:
                row.update(measure_evaluate(spec, args.evaluate_timeout))
            rows.append(row)
            print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()
                              if k not in ("fresh", "late")}), file=sys.stderr, flush=True)
        if svc is not None:
            server = server_memory(svc.proc.pid, rss_start, args.memory_cap)
    finally:
        if svc is not None:
            client.close()
            svc.stop()
    table = markdown(rows, args)
    if svc is not None:
        table += "\n\n" + server
    machine = (f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
               f"load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")
    if args.json:
        print(json.dumps({"machine": machine, "rows": rows}, indent=1, default=str))
    else:
        print(table)
        print(f"\n{machine}")
    if args.out:
        args.out.write_text(table + f"\n\n{machine}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
