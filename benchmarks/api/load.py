"""HTTP service measurements against live servers: load, SIGKILL restarts, upload memory.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/api/load.py [load|restart|memory|all]

Prints one table per run. Servers are started on 127.0.0.1 (free ports, temporary data
directories) with ``python -m service.api.server`` and stopped at the end.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "api"))
from api_helpers import LiveServer, encode, noisy_plane_cloud, noisy_sphere, rss_of  # noqa: E402

MIB = 2**20
OPEN = {
    "GEOSMOOTH_RATE_LIMIT": "100000",
    "GEOSMOOTH_RATE_BURST": "100000",
    "GEOSMOOTH_MAX_SYNC_PER_KEY": "10",
}


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def _wait(client: httpx.Client, job_id: str, timeout: float = 600) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job.get("status") in ("succeeded", "failed", "cancelled"):
            return job  # type: ignore[no-any-return]
        time.sleep(0.25)
    return {"status": "timeout"}


def load(jobs: int = 200, threads: int = 20, sync: int = 100) -> None:
    """``jobs`` submitted from ``threads`` threads, then ``sync`` synchronous smooths."""
    root = Path(tempfile.mkdtemp(prefix="geosmooth-load-"))
    live = LiveServer(root / "data", workers=2, env=OPEN).start()
    pts, faces = noisy_sphere(2)
    body = encode("ply", pts, faces)
    submit_ms: list[float] = []
    ids: list[str] = []
    lock = threading.Lock()

    def one(i: int) -> None:
        with live.client(timeout=120) as c:
            t = time.perf_counter()
            r = c.post(
                "/v1/jobs",
                files={"file": (f"s{i}.ply", body)},
                data={"params": json.dumps({"rms": 0.01})},
            )
            with lock:
                submit_ms.append(1000 * (time.perf_counter() - t))
                if r.status_code == 202:
                    ids.append(r.json()["id"])

    start = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(one, range(jobs)))
    with live.client(timeout=120) as c:
        outcomes = [_wait(c, j)["status"] for j in ids]
        listed = c.get("/v1/jobs", params={"limit": 500}).json()
    wall = time.perf_counter() - start
    sync_ms: list[float] = []

    def smooth(i: int) -> None:
        with live.client(timeout=120) as c:
            t = time.perf_counter()
            r = c.post(
                "/v1/smooth",
                files={"file": ("s.ply", body)},
                data={"params": json.dumps({"rms": 0.01})},
            )
            if r.status_code == 200:
                with lock:
                    sync_ms.append(1000 * (time.perf_counter() - t))

    with ThreadPoolExecutor(10) as pool:
        list(pool.map(smooth, range(sync)))
    live.stop()
    listed_ids = [i["id"] for i in listed["items"]]
    print(
        f"load: {jobs} jobs from {threads} threads ({len(pts)}-point mesh), 2 workers, "
        f"{wall:.1f} s; uptime: {os.getloadavg()[0]:.1f}"
    )
    print(
        f"  accepted {len(ids)}, succeeded {outcomes.count('succeeded')}, failed "
        f"{outcomes.count('failed')}, lost {len(set(ids) - set(listed_ids))}, duplicated "
        f"{len(listed_ids) - len(set(listed_ids)) + max(0, listed['total'] - len(ids))}"
    )
    print(f"  submit latency ms: p50 {_pct(submit_ms, 50):.0f}, p95 {_pct(submit_ms, 95):.0f}")
    print(
        f"  /v1/smooth ({sync} from 10 threads, {len(sync_ms)} ok) ms: p50 "
        f"{_pct(sync_ms, 50):.0f}, p95 {_pct(sync_ms, 95):.0f}"
    )


def restart(kills: int = 5, per_round: int = 20) -> None:
    """Submit while the server is SIGKILLed ``kills`` times; every accepted job must finish."""
    root = Path(tempfile.mkdtemp(prefix="geosmooth-kill-"))
    data = root / "data"
    accepted: list[str] = []
    rng = np.random.default_rng(4)
    for round_ in range(kills + 1):
        live = LiveServer(data, workers=2, env=OPEN).start()
        with live.client(timeout=60) as c:
            for i in range(per_round):
                cloud = noisy_plane_cloud(int(rng.integers(2000, 20000)), seed=100 * round_ + i)
                r = c.post(
                    "/v1/jobs",
                    files={"file": ("c.xyz", encode("xyz", cloud, None))},
                    data={"params": json.dumps({"rms": 0.005, "neighborhood": "knn"})},
                )
                if r.status_code == 202:
                    accepted.append(r.json()["id"])
        if round_ < kills:
            time.sleep(float(rng.uniform(0.2, 1.5)))
            live.kill()
    with live.client(timeout=60) as c:
        outcomes = [_wait(c, j)["status"] for j in accepted]
    live.stop()
    print(
        f"restart: {kills} SIGKILLs while submitting and running, {len(accepted)} accepted, "
        f"{outcomes.count('succeeded')} succeeded, {outcomes.count('failed')} failed, "
        f"{len(accepted) - len(outcomes)} lost"
    )


def _sample_rss(live: LiveServer, stop: threading.Event, out: dict[str, int]) -> None:
    assert live.proc is not None
    while not stop.is_set():
        out["server"] = max(out.get("server", 0), rss_of(live.proc.pid))
        stop.wait(0.02)


def memory() -> None:
    """Server RSS while 1 GiB is streamed at a 256 MiB limit; peak RSS per MiB uploaded."""
    root = Path(tempfile.mkdtemp(prefix="geosmooth-mem-"))
    live = LiveServer(root / "data", workers=2, env=OPEN).start()
    assert live.proc is not None
    base = rss_of(live.proc.pid)
    peak: dict[str, int] = {}
    stop = threading.Event()
    sampler = threading.Thread(target=_sample_rss, args=(live, stop, peak), daemon=True)
    sampler.start()
    chunk = b"0.125 0.25 0.5\n" * 70_000

    def body() -> Iterator[bytes]:
        yield b'--b\r\nContent-Disposition: form-data; name="file"; filename="a.xyz"\r\n\r\n'
        for _ in range(1024):
            yield chunk

    with live.client(timeout=600) as c:
        try:
            r = c.post(
                "/v1/jobs",
                content=body(),
                headers={"content-type": "multipart/form-data; boundary=b"},
            )
            status = r.status_code
        except httpx.HTTPError as exc:
            status = type(exc).__name__
    print(
        f"memory: 1 GiB chunked upload at the 256 MiB limit -> {status}; server RSS "
        f"{base / MIB:.0f} MiB before, peak {peak['server'] / MIB:.0f} MiB"
    )
    rows = []
    for label, fmt, n in (
        ("xyz text", "xyz", 2_000_000),
        ("binary ply", "ply", 2_000_000),
        ("json", "json", 400_000),
    ):
        cloud = noisy_plane_cloud(n, seed=8)
        data = _binary_ply(cloud) if fmt == "ply" else encode(fmt, cloud, None)
        peak.clear()
        before = rss_of(live.proc.pid)
        with live.client(timeout=600) as c:
            r = c.post(
                "/v1/jobs",
                files={"file": (f"big.{fmt}", data)},
                data={"params": json.dumps({"lam": 1.0, "neighborhood": "knn"})},
            )
            if r.status_code == 202:
                c.delete(f"/v1/jobs/{r.json()['id']}")
        worker = [x for x in live.records() if x.get("event") == "request.worker"][-1]
        grown = worker["rss_peak_mib"] - worker["rss_start_mib"]
        rows.append(
            (
                label,
                len(data) / MIB,
                r.status_code,
                (peak["server"] - before) / MIB,
                grown,
                grown / (len(data) / MIB),
                worker["seconds"],
            )
        )
    stop.set()
    live.stop()
    print("  upload        MiB  status  server +MiB  parser +MiB  parser MiB/MiB  parse s")
    for row in rows:
        print("  {:<11} {:6.1f}  {:6}  {:11.1f}  {:11.1f}  {:14.2f}  {:7.2f}".format(*row))


def _binary_ply(points: np.ndarray) -> bytes:
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n"
    )
    return head.encode() + np.ascontiguousarray(points, "<f8").tobytes()


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    for name, run in (("load", load), ("restart", restart), ("memory", memory)):
        if which in (name, "all"):
            run()
