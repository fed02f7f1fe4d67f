"""Record the stage timeline of ``geosmooth smooth --progress json`` runs (issue 41 item 6).

Each run is a synthetic airborne-like LAS (UTM 32N, a 110 m square per 1M points of density
~80 points/m², terrain of two sines, 2 cm noise, 60 % ground class): the events (stage, step,
elapsed seconds, relative error) go to ``benchmarks/progress/runs/<name>.json`` with the run's
CPU seconds and the load. ``service.core.progress`` takes its stage shares from the calibration
runs; ``tests/core/test_progress_model.py`` replays the others.

    python -m benchmarks.progress.record 10000 30000 100000 300000 1000000 --tiled 300000
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

RUNS = Path(__file__).with_name("runs")


def make_las(path: Path, n: int, seed: int = 0) -> None:
    import laspy
    import pyproj

    rng = np.random.default_rng(seed)
    side = 110.0 * np.sqrt(n / 1e6)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_crs(pyproj.CRS.from_epsg(32632))
    header.scales = np.array([0.001] * 3)
    header.offsets = np.array([500000.0, 5000000.0, 0.0])
    las = laspy.LasData(header)
    x, y = rng.random(n) * side, rng.random(n) * side
    las.x, las.y = 500000 + x, 5000000 + y
    las.z = 10 + 0.5 * np.sin(x / 7) + 0.3 * np.cos(y / 5) + rng.normal(0, 0.02, n)
    las.classification = np.where(rng.random(n) < 0.6, 2, 5).astype(np.uint8)
    las.write(path)


def record(n: int, tiled: bool) -> dict[str, object]:
    name = f"las-{n // 1000}k" + ("-tiled" if tiled else "")
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "in.las"
        make_las(src, n)
        cmd = [sys.executable, "-m", "service.cli", "smooth", str(src), "-o",
               str(Path(tmp) / "out.las"), "--progress", "json"]  # fmt: skip
        if tiled:
            cmd += ["--tile-points", str(max(n // 3, 50_000))]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    events, summary = [], ""
    for line in done.stderr.splitlines():
        r = json.loads(line)
        summary = r.get("text", summary)
        if r["event"] in ("stage", "iteration"):
            events.append({k: r.get(k) for k in ("event", "stage", "step", "elapsed_seconds",
                                                  "relative_error")})  # fmt: skip
    run = {
        "name": name, "points": n, "tiled": tiled, "events": events,
        "wall_seconds": float(re.search(r"time ([\d.]+) s \(read", summary)[1]),  # type: ignore[index]
        "cpu_seconds": round((after.ru_utime + after.ru_stime)
                             - (before.ru_utime + before.ru_stime), 2),
        "load": os.getloadavg()[0],
    }  # fmt: skip
    (RUNS / f"{name}.json").write_text(json.dumps(run, indent=1) + "\n")
    return run


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("points", type=int, nargs="*")
    parser.add_argument("--tiled", type=int, nargs="*", default=[])
    ns = parser.parse_args()
    RUNS.mkdir(exist_ok=True)
    for n, tiled in [(n, False) for n in ns.points] + [(n, True) for n in ns.tiled]:
        run = record(n, tiled)
        print(run["name"], run["wall_seconds"], "s wall", run["cpu_seconds"], "s CPU, load",
              run["load"], flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
