"""A large LAS through ``geosmooth smooth --tile-points`` (the streamed path).

``python -m benchmarks.tiles.las_run make N PATH``: a terrain LAS of ``N`` points (point format
3: intensity, returns, classification, GPS time, RGB; 0.5 m spacing, noise 5 cm).
``python -m benchmarks.tiles.las_run run PATH TILE_POINTS WORKERS TAU``: the CLI on it with
``GEOSMOOTH_TILE_WORKERS=WORKERS``; wall time and the peak of the summed RSS of the CLI and its
tile processes (sampled from /proc every 0.2 s). One JSON line is appended to
``benchmarks/tiles/results/las.jsonl``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.tiles import terrain

OUT = Path(__file__).resolve().parent / "results" / "las.jsonl"


def make(n: int, path: Path) -> None:
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([500000.0, 5000000.0, 0.0])
    rng = np.random.default_rng(1)
    with laspy.open(str(path), mode="w", header=header) as writer:
        P = terrain.cloud(n)
        for at in range(0, n, 1 << 21):
            k = min(1 << 21, n - at)
            rec = laspy.ScaleAwarePointRecord.zeros(k, header=header)
            rec.x = P[at : at + k, 0] + 500000.0
            rec.y = P[at : at + k, 1] + 5000000.0
            rec.z = P[at : at + k, 2]
            rec.intensity = rng.integers(0, 65535, k, dtype=np.uint16)
            rec.classification = np.full(k, 2, np.uint8)
            rec.gps_time = np.sort(rng.uniform(0, 1e5, k))
            rec.red = rng.integers(0, 65535, k, dtype=np.uint16)
            writer.write_points(rec)


def _tree_rss(pid: int) -> int:
    """Summed RSS (bytes) of ``pid`` and its descendants."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        try:
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
        except OSError:
            pass
        todo.extend(children.get(p, []))
    return total


def run(path: Path, tile_points: int, workers: int, tau: float) -> None:
    out = path.with_name(path.stem + f"-out-{workers}.las")
    report = path.with_name(path.stem + f"-report-{workers}.json")
    exe = Path(sys.executable).with_name("geosmooth")
    env = {**os.environ, "GEOSMOOTH_TILE_WORKERS": str(workers)}
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(exe), "smooth", str(path), "-o", str(out), "--tau", str(tau),
                             "--tile-points", str(tile_points), "--report", str(report), "-q"],
                            env=env)  # fmt: skip
    peak = 0
    while proc.poll() is None:
        peak = max(peak, _tree_rss(proc.pid))
        time.sleep(0.2)
    seconds = time.perf_counter() - t0
    rep = json.loads(report.read_text()) if report.exists() else {}
    n = rep.get("n_points", 0)
    row = {"input": str(path), "n": n, "tile_points": tile_points, "workers": workers,
           "exit": proc.returncode, "seconds": seconds, "points_per_second": n / seconds,
           "peak_rss_mb": peak / 2**20, "phi_rel": rep.get("relative_error"),
           "tiles": rep.get("tiles", {}).get("count"),
           "rounds": rep.get("tiles", {}).get("rounds"),
           "halo_hops": rep.get("tiles", {}).get("halo_hops"),
           "tile_seconds": [round(t["seconds"], 2) for t in rep.get("tiles", {}).get("tiles", [])],
           "tile_points_with_halo": [t["points"] + t["halo"]
                                     for t in rep.get("tiles", {}).get("tiles", [])],
           "load": os.getloadavg()[0], "when": time.strftime("%Y-%m-%d %H:%M:%S")}  # fmt: skip
    print(json.dumps(row), flush=True)
    with open(OUT, "a") as fh:
        fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(int(sys.argv[2]), Path(sys.argv[3]))
    else:
        run(Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5]))
