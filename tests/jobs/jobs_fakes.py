"""A scripted job function for testing the queue machinery without the solver.

The job's input file (format ``json``) is a script, e.g. ``{"action": "sleep", "seconds": 5}``:

* ``ok``: report progress ``steps`` times, ``seconds`` in total, write ``result.npy``, succeed
* ``sleep``: like ``ok`` (long ``seconds``: for cancel, timeout, restart tests)
* ``raise``: raise ``RuntimeError``
* ``core_error``: raise the core's ``TauOutOfRange``
* ``exit``: ``os._exit(code)`` (a crash that records nothing)
* ``segfault``: kill itself with SIGSEGV
* ``kill_server``: SIGKILL the server whose pid is in ``<data_dir>/server.pid`` (poison job)
* ``oom_once``: the first run SIGKILLs itself (as the OOM killer would), the next ones succeed
* ``hog``: allocate ``bytes`` bytes (fails under a smaller memory cap)

``ok``/``sleep`` with ``extra_bytes`` also write an output file of that size.

Every run appends its pid to ``<job_dir>/pids`` and ``start <pid> <t>`` / ``end <pid> <t>``
lines to ``<job_dir>/runs`` (to check that no two runs of a job overlap).
"""

from __future__ import annotations

import io
import json
import os
import signal
import time
from typing import Any

import numpy as np

from service.core.errors import TauOutOfRange
from service.core.progress import ProgressEvent
from service.jobs.runner import JobContext, smooth_job


def _runs(ctx: JobContext) -> list[str]:
    return (ctx.job_dir / "pids").read_text().split()


def script(action: str, **kw: Any) -> bytes:
    """Input bytes for :func:`scripted`."""
    return json.dumps({"action": action, **kw}).encode()


def scripted(ctx: JobContext) -> dict[str, Any]:
    """Do what the input file says (see the module docstring)."""
    spec = json.loads(ctx.input_path.read_text())
    with open(ctx.job_dir / "pids", "a") as fh:
        fh.write(f"{os.getpid()}\n")
    _log_run(ctx, "start")
    report = _act(ctx, spec)
    _log_run(ctx, "end")
    return report


def scripted_or_real(ctx: JobContext) -> dict[str, Any]:
    """:func:`scripted` for a script input, else the real job (one worker pool serves both)."""
    if ctx.fmt == "json":
        try:
            spec = json.loads(ctx.input_path.read_text())
        except ValueError:
            spec = None
        if isinstance(spec, dict) and "action" in spec:
            return scripted(ctx)
    return smooth_job(ctx)


def _log_run(ctx: JobContext, what: str) -> None:
    with open(ctx.job_dir / "runs", "a") as fh:
        fh.write(f"{what} {os.getpid()} {time.time():.6f}\n")
        fh.flush()
        os.fsync(fh.fileno())


def _act(ctx: JobContext, spec: dict[str, Any]) -> dict[str, Any]:
    action = spec["action"]
    if action == "raise":
        raise RuntimeError("boom\nsecond line of a long story")
    if action == "core_error":
        raise TauOutOfRange("tau 5 is outside (0, 2)", field="params.tau", tau=5.0, tau_max=2.0)
    if action == "exit":
        os._exit(int(spec.get("code", 1)))
    if action == "segfault":
        os.kill(os.getpid(), signal.SIGSEGV)
        time.sleep(5)
    if action == "kill_server":
        server = int((ctx.job_dir.parent.parent / "server.pid").read_text())
        os.kill(server, signal.SIGKILL)
        time.sleep(30)
    if action == "oom_once" and len(_runs(ctx)) == 1:  # killed like the OOM killer does, once
        os.kill(os.getpid(), signal.SIGKILL)
    if action == "hog":  # allocate (and touch) more than the memory cap allows
        block = np.ones(int(spec["bytes"]) // 8)
        return {"phi": float(block.sum()), "tau": None, "iterations": 0}
    steps = int(spec.get("steps", 5))
    seconds = float(spec.get("seconds", 0.0))
    tau = ctx.params.tau
    phi = 10.0
    for i in range(1, steps + 1):
        time.sleep(seconds / steps)
        phi = tau + (phi - tau) / 4 if tau else phi / 2
        ctx.progress(ProgressEvent("search", tau=tau, iteration=i, lam=1.0 / i, phi=phi))
    ctx.flush_progress()
    buf = io.BytesIO()
    np.save(buf, np.arange(6, dtype=np.float64).reshape(3, 2))
    ctx.write("result.npy", buf.getvalue())
    if spec.get("extra_bytes"):  # a large output (e.g. one that does not fit a full disk)
        ctx.write("extra.bin", b"\0" * int(spec["extra_bytes"]))
    rel = abs(phi - tau) / tau if tau else None
    return {"phi": phi, "tau": tau, "lambda": 1.0 / steps, "relative_error": rel,
            "iterations": steps}  # fmt: skip
