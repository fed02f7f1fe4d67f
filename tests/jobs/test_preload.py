"""``service.jobs.preload``: the forkserver's warm-up loads every compiled kernel a job or an
upload can reach, so that no job or request process compiles one (a compile costs seconds of the
request's CPU limit; in a fresh install, with no numba cache yet, more than a minute on a loaded
machine)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: Every module of the engine that defines compiled kernels (found, so a new one is checked too).
COMPILED = sorted(
    ".".join(path.relative_to(ROOT).with_suffix("").parts)
    for path in (ROOT / "service").rglob("*.py")
    if "@njit" in path.read_text(encoding="utf-8")
)

PROBE = """
import importlib, inspect, json, sys
import service.jobs.preload  # the warm-up runs on import
from numba.core.registry import CPUDispatcher
out = {}
for name in sys.argv[1:]:
    mod = importlib.import_module(name)
    kernels = {k: v for k, v in vars(mod).items() if isinstance(v, CPUDispatcher)}
    for fname, func in vars(mod).items():
        if inspect.isfunction(func) and func.__module__ == name:
            for used in set(func.__code__.co_names) & set(kernels):
                out[f"{name}.{used}"] = len(kernels[used].signatures)
    for public in set(getattr(mod, "__all__", ())) & set(kernels):
        out[f"{name}.{public}"] = len(kernels[public].signatures)
print(json.dumps(out))
"""


def test_every_kernel_called_from_python_is_compiled_by_the_warm_up() -> None:
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *COMPILED], cwd=ROOT, capture_output=True, text=True,
        check=True,
    )  # fmt: skip
    called = json.loads(done.stdout.strip().splitlines()[-1])
    # the entry points of each module (callees inlined into them have no signature of their own)
    assert {"service.core.operator.knn_kernels.grid_query",
            "service.core.noise.fast_fits._surface_fits",
            "service.core.noise.fast_weights._isolation",
            "service.core.system.fast_frames._normals"} <= set(called)  # fmt: skip
    cold = sorted(k for k, count in called.items() if count == 0)
    assert not cold, f"compiled on first use in each job process: {cold}"


def test_the_neighbourhood_kernels_are_compiled_by_the_warm_up() -> None:
    """Below 50,000 points a run takes the NumPy kernels of ``operator.sized_kernels``, so the
    warm-up's tiny smooths no longer compile ``operator.kernels``; once numba is loaded every
    run of the process takes the compiled ones, so the warm-up calls each itself."""
    probe = (
        "import json, service.jobs.preload\n"
        "from numba.core.registry import CPUDispatcher\n"
        "from service.core.operator import kernels\n"
        "print(json.dumps({k: len(v.signatures) for k, v in vars(kernels).items()\n"
        "                  if isinstance(v, CPUDispatcher) and k in kernels.__all__}))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True
    )
    called = json.loads(done.stdout.strip().splitlines()[-1])
    assert {"mesh_rings", "neighbourhood_covariances", "polar_hull_fans",
            "rows_from_pairs"} <= set(called)  # fmt: skip
    assert all(count > 0 for count in called.values()), called
