"""Start-up cost of the ``geosmooth`` command on small inputs (issue 30 item 4).

Each case runs ``python -m service.cli ...`` in a fresh process ``--runs`` times and reports
the CPU seconds (user + system, from ``wait4``) and the peak resident memory of the process.
``--before DIR`` runs the same cases on another checkout (e.g. ``git archive`` of the base
commit unpacked into DIR), alternating the two trees case by case, so the load is comparable::

    python -m benchmarks.speed.startup --runs 7 --before /tmp/before

The inputs are a 200-point noisy helix (XYZ, written here) and the two samples; ``--help`` and
``smooth --help`` are the two help screens. The load average is printed before and after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _cases(tmp: Path) -> dict[str, list[str]]:
    t = np.linspace(0, 6 * np.pi, 200)
    rng = np.random.default_rng(0)
    helix = np.c_[np.cos(t), np.sin(t), 0.1 * t] + 0.01 * rng.standard_normal((200, 3))
    np.savetxt(tmp / "helix.xyz", helix)
    cli = ["-m", "service.cli"]
    return {
        "smooth helix, 200 points (XYZ)": [*cli, "smooth", "-q", str(tmp / "helix.xyz"), "-o",
                                           str(tmp / "o.xyz")],
        "smooth noisy-sphere.ply, 642 vertices": [
            *cli, "smooth", "-q", "{tree}/service/samples/noisy-sphere.ply", "-o",
            str(tmp / "o.ply"),
        ],
        "smooth noisy-helix.obj": [*cli, "smooth", "-q", "{tree}/service/samples/noisy-helix.obj",
                                   "-o", str(tmp / "o.obj")],
        "--help": [*cli, "--help"],
        "smooth --help": [*cli, "smooth", "--help"],
    }  # fmt: skip


def run_once(tree: Path, args: list[str]) -> tuple[float, float]:
    """CPU seconds and peak RSS (MiB) of one ``python ARGS`` process run in ``tree``."""
    env = dict(os.environ, PYTHONPATH=f"{tree}{os.pathsep}{tree}/clients/python")
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.chdir(tree)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        os.execve(sys.executable, [sys.executable, *(a.format(tree=tree) for a in args)], env)
    _, status, usage = os.wait4(pid, 0)
    if status != 0:
        raise RuntimeError(f"{args} failed in {tree} (status {status})")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--before", type=Path, help="another checkout to compare with")
    ns = parser.parse_args(argv)
    trees = {"after": ROOT} if ns.before is None else {"before": ns.before, "after": ROOT}
    print("load average before: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    print("| case | tree | CPU s min | CPU s median | peak RSS MiB |\n|---|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, args in _cases(Path(tmp)).items():
            results: dict[str, list[tuple[float, float]]] = {label: [] for label in trees}
            for _ in range(ns.runs):
                for label, tree in trees.items():
                    results[label].append(run_once(tree, args))
            for label, res in results.items():
                cpu = [r[0] for r in res]
                rss = statistics.median(r[1] for r in res)
                print(f"| {name} | {label} | {min(cpu):.3f} | {statistics.median(cpu):.3f} "
                      f"| {rss:.0f} |")  # fmt: skip
    print("load average after: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))


if __name__ == "__main__":
    main()
