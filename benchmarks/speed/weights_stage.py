"""The data-weights stage of the default path alone (issue 30 item 3): CPU seconds, peak RSS.

``PYTHONPATH=<tree> python -m benchmarks.speed.weights_stage [input ...] [--profile N]``
(inputs as :mod:`benchmarks.speed.jobs` names them; default ``torus:1000 ico:7``) prints one
JSON line per input: :func:`service.core.noise.robust.data_weights` with the default
parameters, the noise estimate included (its memo cleared; in a run the data weights ask for
it first), one thread, ``time.process_time``, median of ``--repeat`` runs after a warm-up on a
60K torus (numba's compilation is not counted); the peak RSS of the stage over the RSS before
it (``ru_maxrss``: the first timed run), the load average, and with ``--profile N`` the ``N``
functions of largest cumulative time (cProfile on ``process_time``, a separate run).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import resource
import time

import numpy as np
from threadpoolctl import threadpool_limits

from benchmarks.speed.jobs import INPUTS
from service.core import SmoothingParams
from service.core.noise import estimate
from service.core.noise.robust import data_weights


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _run(g, params):  # type: ignore[no-untyped-def]
    estimate._MEMO.clear()
    c0 = time.process_time()
    got, dw = data_weights(g, params.data)
    return time.process_time() - c0, got, dw


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("inputs", nargs="*", default=["torus:1000", "ico:7"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--profile", type=int, default=0)
    a = ap.parse_args(argv)
    threadpool_limits(1)
    params = SmoothingParams()
    _run(INPUTS["torus"]("400")[0], params)  # warm-up (53K): compile / load the kernels
    for name in a.inputs:
        kind, _, arg = name.partition(":")
        g = INPUTS[kind](arg)[0]
        before = _rss_mib()
        cpu = [_run(g, params)[0]]
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - before
        for _ in range(a.repeat - 1):
            cpu.append(_run(g, params)[0])
        _, got, dw = _run(g, params)
        out = {
            "input": name, "n": g.n, "cpu_median": round(float(np.median(cpu)), 3),
            "cpu": [round(c, 3) for c in cpu], "peak_rss_over_mib": round(peak, 1),
            "load": os.getloadavg()[0],
            "applied": None if dw is None else dw.robust, "uneven": None if dw is None
            else dw.uneven, "outliers": None if dw is None else int(dw.outliers.size),
            "spread": None if dw is None else dw.spread,
            "omega_sum": float(np.sum(got.omega())),
        }  # fmt: skip
        if a.profile:
            estimate._MEMO.clear()
            prof = cProfile.Profile(time.process_time)
            prof.enable()
            data_weights(g, params.data)
            prof.disable()
            st = pstats.Stats(prof).stats  # type: ignore[attr-defined]
            rows = sorted(((v[3], v[2], f"{fn[0].split('/')[-1]}:{fn[2]}")
                           for fn, v in st.items()), reverse=True)[: a.profile]  # fmt: skip
            out["profile"] = [(name, round(cum, 3), round(tot, 3)) for cum, tot, name in rows]
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
