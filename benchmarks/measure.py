"""Measuring: child processes with their own peak RSS, and a description of the machine."""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import json
import os
import platform
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["ChildResult", "machine_info", "package_versions", "run_child", "self_peak_rss_mb"]

PACKAGES = (
    "numpy",
    "scipy",
    "scikit-sparse",
    "trimesh",
    "open3d",
    "pymeshlab",
    "sparseqr",
    "scikit-umfpack",
    "psutil",
)


@dataclass
class ChildResult:
    """Outcome of one configuration run in a fresh interpreter.

    Attributes
    ----------
    status : str
        ``"ok"``, ``"timeout"`` or ``"error"``.
    data : dict
        What the child wrote (empty unless ``status == "ok"``).
    peak_rss_mb : float
        Peak RSS of the child in MiB: its own ``VmHWM`` as it reported it at the end, else
        ``ru_maxrss`` from ``os.wait4`` on its pid.
    ru_maxrss_mb : float
        ``ru_maxrss`` of that child alone (``os.wait4``). On Linux it includes the parent's RSS
        at ``fork`` time (see :func:`self_peak_rss_mb`), so it is only an upper bound.
    wall : float
        Wall-clock seconds of the child, interpreter start-up included.
    error : str
        Tail of the child's stderr when it failed.
    """

    status: str
    data: dict[str, Any]
    peak_rss_mb: float
    ru_maxrss_mb: float
    wall: float
    error: str = ""


def self_peak_rss_mb() -> float:
    """Peak RSS of the calling process's own address space so far, in MiB.

    On Linux this is ``VmHWM`` from ``/proc/self/status``. ``getrusage(...).ru_maxrss`` is not
    used there because Linux carries the parent's RSS high-water mark over ``fork`` + ``exec``
    into the child's ``ru_maxrss``: a child of a parent that holds a large mesh would report at
    least the parent's size. Elsewhere ``ru_maxrss`` is the fallback.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    import resource

    scale = 1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale


def run_child(spec: dict[str, Any], workdir: Path, timeout: float) -> ChildResult:
    """Run ``python -m benchmarks.worker SPEC OUT`` and collect its result and peak RSS.

    The child reports its own peak RSS (``VmHWM``); ``os.wait4`` on its pid gives its
    ``ru_maxrss`` as well (``RUSAGE_CHILDREN`` would give the maximum over all children so far).

    Parameters
    ----------
    spec : dict
        JSON-serializable job for :mod:`benchmarks.worker`.
    workdir : Path
        Directory for the spec, output and log files.
    timeout : float
        Seconds after which the child is killed (status ``"timeout"``).
    """
    stamp = f"{os.getpid()}-{time.monotonic_ns()}"
    spec_path = workdir / f"spec-{stamp}.json"
    out_path = workdir / f"out-{stamp}.json"
    log_path = workdir / f"log-{stamp}.txt"
    spec_path.write_text(json.dumps(spec))
    root = Path(__file__).resolve().parent.parent
    env = dict(os.environ)
    env["PYTHONPATH"] = str(root) + os.pathsep + env.get("PYTHONPATH", "")
    t0 = time.perf_counter()
    with log_path.open("wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.worker", str(spec_path), str(out_path)],
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=root,
            env=env,
        )
        status = "ok"
        while True:
            pid, code, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t0 > timeout:
                os.kill(proc.pid, signal.SIGKILL)
                pid, code, usage = os.wait4(proc.pid, 0)
                status = "timeout"
                break
            time.sleep(0.02)
        proc.returncode = os.waitstatus_to_exitcode(code)
    wall = time.perf_counter() - t0
    rss = usage.ru_maxrss / 1024.0
    if status == "ok" and (proc.returncode != 0 or not out_path.is_file()):
        status = "error"
    data: dict[str, Any] = json.loads(out_path.read_text()) if status == "ok" else {}
    error = ""
    if status == "error":
        lines = log_path.read_text(errors="replace").strip().splitlines()
        error = lines[-1] if lines else f"exit code {proc.returncode}"
    peak = float(data.get("rss_self_mb", rss))
    return ChildResult(status, data, peak, rss, wall, error)


def package_versions() -> dict[str, str | None]:
    """Installed versions of the packages the benchmarks use (``None`` when missing)."""
    out: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _memory_gib() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) / 1024.0**2
    except OSError:
        pass
    return None


def _blas() -> str:
    link = Path("/etc/alternatives/libblas.so.3-x86_64-linux-gnu")
    try:
        return str(link.resolve())
    except OSError:
        return "unknown"


def machine_info() -> dict[str, Any]:
    """Date, CPU, cores, memory, OS, Python, BLAS, package versions and current load."""
    mem = _memory_gib()
    return {
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "memory_gib": None if mem is None else round(mem, 1),
        "os": platform.platform(),
        "python": platform.python_version(),
        "system_blas": _blas(),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "packages": package_versions(),
    }
