"""A scripted job function for testing the queue machinery without the solver.

The job's input file (format ``json``) is a script, e.g. ``{"action": "sleep", "seconds": 5}``:

* ``ok``: report progress ``steps`` times, ``seconds`` in total, write ``result.npy``, succeed
* ``sleep``: like ``ok`` (long ``seconds``: for cancel, timeout, restart tests)
* ``raise``: raise ``RuntimeError``
* ``core_error``: raise the core's ``TauOutOfRange``
* ``exit``: ``os._exit(code)`` (a crash that records nothing)
* ``segfault``: kill itself with SIGSEGV
* ``kill_server``: SIGKILL the server whose pid is in ``<data_dir>/server.pid`` (poison job)

Every run appends its pid to ``<job_dir>/pids`` and a line to ``<job_dir>/runs``.
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
from service.jobs.runner import JobContext


def script(action: str, **kw: Any) -> bytes:
    """Input bytes for :func:`scripted`."""
    return json.dumps({"action": action, **kw}).encode()


def scripted(ctx: JobContext) -> dict[str, Any]:
    """Do what the input file says (see the module docstring)."""
    spec = json.loads(ctx.input_path.read_text())
    with open(ctx.job_dir / "pids", "a") as fh:
        fh.write(f"{os.getpid()}\n")
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
    rel = abs(phi - tau) / tau if tau else None
    return {"phi": phi, "tau": tau, "lambda": 1.0 / steps, "relative_error": rel,
            "iterations": steps}  # fmt: skip
