"""``python -m benchmarks.queue [--rounds 3] [--repeat 2] [--out benchmarks/results]``.

Throughput of a job mix on 1 and 2 workers (RQ and embedded), per-job overhead of RQ against
the embedded queue, and Redis's cost per job. Prints a markdown summary and writes
``<out>/queue-<date>.json``. Needs redis-server; about 5 minutes on a quiet 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from benchmarks.measure import machine_info
from benchmarks.queue.run import job_mix, overhead, redis_cost, throughput, utilization


def main(argv: list[str] | None = None) -> int:
    """Run the queue benchmark; returns the exit code."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.queue")
    ap.add_argument("--rounds", type=int, default=3, help="runs of the mix per setting")
    ap.add_argument("--repeat", type=int, default=2, help="copies of the 6-job mix per run")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    ap.add_argument("--summarize", type=Path, help="print the summary of an earlier result")
    ns = ap.parse_args(argv)
    if ns.summarize:
        print(summary(json.loads(ns.summarize.read_text())))
        return 0
    jobs = job_mix(ns.repeat)
    result: dict[str, object] = {"machine": machine_info(), "jobs_per_run": len(jobs)}
    for backend in ("embedded", "rq"):
        for n in (1, 2):
            print(f"throughput {backend} x{n} ...", file=sys.stderr, flush=True)
            result[f"{backend}_{n}"] = throughput(jobs, n, backend, ns.rounds)
    for backend in ("embedded", "rq"):
        one, two = result[f"{backend}_1"], result[f"{backend}_2"]
        result[f"{backend}_scaling"] = two["jobs_per_s"] / one["jobs_per_s"]  # type: ignore[index]
    print("overhead ...", file=sys.stderr, flush=True)
    result["overhead"] = overhead()
    result["redis"] = redis_cost(jobs)
    result["machine_after"] = {"load_average": machine_info()["load_average"]}
    ns.out.mkdir(parents=True, exist_ok=True)
    path = ns.out / f"queue-{time.strftime('%Y-%m-%d')}.json"
    path.write_text(json.dumps(result, indent=1, default=str))
    print(summary(result))
    print(f"wrote {path}", file=sys.stderr)
    return 0


def summary(r: dict) -> str:  # type: ignore[type-arg]
    """A markdown table of the results."""
    lines = ["| backend | workers | jobs/s | p50 latency s | p95 latency s | scaling | "
             "worker utilization |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for backend in ("embedded", "rq"):
        for n in (1, 2):
            x = r[f"{backend}_{n}"]
            scale = f"{r[f'{backend}_scaling']:.2f}" if n == 2 else ""
            use = sorted(utilization(run, n) for run in x["rounds"])
            lines.append(f"| {backend} | {n} | {x['jobs_per_s']:.2f} | {x['p50_s']:.2f} | "
                         f"{x['p95_s']:.2f} | {scale} | {use[len(use) // 2]:.2f} "
                         f"({use[0]:.2f}-{use[-1]:.2f}) |")  # fmt: skip
    lines.append(f"load average before/after: {r['machine']['load_average']} / "
                 f"{r['machine_after']['load_average']} on {r['machine']['cores']} cores")
    o, red = r["overhead"], r["redis"]
    lines.append("")
    lines.append(f"tiny job latency: embedded {o['embedded']['latency_s'] * 1e3:.0f} ms, RQ "
                 f"{o['rq']['latency_s'] * 1e3:.0f} ms (RQ overhead "
                 f"{o['rq_overhead_per_job_s'] * 1e3:.0f} ms/job); Redis per job: "
                 f"{red['commands_per_job']:.0f} commands, {red['redis_cpu_s_per_job'] * 1e3:.1f} "
                 f"ms CPU, {red['redis_bytes_per_job'] / 1024:.1f} KiB")  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
