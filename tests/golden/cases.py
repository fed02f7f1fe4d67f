"""The golden cases: engine outputs whose bytes a refactoring must not change (issue 29).

Each case smooths one input with one parameter set through :func:`geosmooth.smooth` (the
library facade, so the public entry point is what is pinned) and records

* ``points``: SHA-256 of the output points (float64, C order);
* ``report``: SHA-256 of a canonical JSON of the report's numeric core (lambda, phi, tau,
  iterations, sigma, the displacement statistics and the warnings), so a change of the
  numbers *or* of what the user is told shows up;
* ``file``: for the shared files, SHA-256 of the bytes written back in the input's format.

``QUICK`` runs in the test suite (about a minute on 2 quiet cores); ``FULL`` adds the quality
benchmark's full grid, its issue-21 halves and the speed benchmark's job set and is run by hand
before and after an engine change::

    python -m tests.golden.cases --write            # QUICK, rewrite hashes
    python -m tests.golden.cases --set full --write

Hashes are only meaningful on one kind of machine (the project's Debian 12, OpenBLAS, 1 thread);
an intended change of the engine's numbers regenerates them in the same commit, with the reason.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tests.shared_data import shared_data_dir

HERE = Path(__file__).resolve().parent
HASHES = {"quick": HERE / "hashes-quick.json", "full": HERE / "hashes-full.json"}

#: The report's members pinned by the hash (the numeric core and what the user is told).
REPORT_KEYS = (
    "n_points",
    "lambda",
    "phi",
    "tau",
    "iterations",
    "converged",
    "history",
    "solver",
    "displacement",
    "sigma_estimate",
    "noise_found",
    "rms_displacement",
    "max_displacement",
    "warnings",
    "shape_warnings",
    "outlier_count",
)


def shared_data() -> Path:
    """The shared real data (``tests/shared_data.py``: ``$GEOSMOOTH_SHARED_DATA``, else
    ``../shared/data`` beside the checkout)."""
    return shared_data_dir()


@dataclass(frozen=True)
class Golden:
    """One golden case: a name, a builder of ``(input, params)`` and whether to hash a file."""

    name: str
    build: Callable[[], tuple[Any, dict[str, Any]]]
    file_format: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _canonical(value: Any) -> Any:
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, dict):
        return {k: _canonical(v) for k, v in sorted(value.items())}
    if isinstance(value, list | tuple):
        return [_canonical(v) for v in value]
    if isinstance(value, np.generic):
        return _canonical(value.item())
    return value


def run_case(case: Golden) -> dict[str, str]:
    """The hashes of one case (see the module docstring)."""
    import geosmooth
    from service.core.errors import GeosmoothError

    source, params = case.build()
    try:
        smoothed, result = geosmooth.smooth(source, params, full_output=True)
    except GeosmoothError as exc:  # a refusal is an output too: pin its class and message
        return {"error": _digest(f"{type(exc).__name__}: {exc}".encode())}
    points = np.ascontiguousarray(result.points, dtype=np.float64)
    report = result.report()
    core = {k: report.get(k) for k in REPORT_KEYS}
    out = {
        "points": _digest(points.tobytes()),
        "report": _digest(json.dumps(_canonical(core), sort_keys=True).encode()),
    }
    if case.file_format is not None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"out.{case.file_format}"
            geosmooth.write(smoothed, path)
            out["file"] = _digest(path.read_bytes())
    return out


# --------------------------------------------------------------------------- the cases


def _quality(key: str, params: dict[str, Any]) -> Callable[[], tuple[Any, dict[str, Any]]]:
    def build() -> tuple[Any, dict[str, Any]]:
        from benchmarks.quality.cases import make_case
        from benchmarks.quality.ours import geometry_of

        case = make_case(key)
        kw = dict(params)
        if kw.pop("rms_sigma", None):
            kw["rms"] = case.sigma
        return geometry_of(case), kw

    return build


def _speed(name: str) -> Callable[[], tuple[Any, dict[str, Any]]]:
    def build() -> tuple[Any, dict[str, Any]]:
        from benchmarks.speed.jobs import JOB_SETS, build_input

        job = next(j for s in JOB_SETS.values() for j in s() if j.name == name)
        g, rms = build_input(job)
        return g, {"rms": rms, **job.params}

    return build


Builder = Callable[[], tuple[Any, dict[str, Any]]]


def _shared(file: str, params: dict[str, Any], **options: Any) -> Builder:
    def build() -> tuple[Any, dict[str, Any]]:
        import geosmooth

        return geosmooth.read(shared_data() / file, **options), dict(params)

    return build


_QUALITY_MODES: dict[str, dict[str, Any]] = {
    "default": {},
    "report-rms": {"preset": "report", "rms_sigma": True},
    "free2-rms": {"displacement": "free", "order": 2, "rms_sigma": True},
    "normal2-rms": {"displacement": "normal", "order": 2, "rms_sigma": True},
}

_QUICK_QUALITY = [
    "sphere-2.5K/aniso-0.5",
    "torus-5.8K/aniso-0.5",
    "fandisk/aniso-0.25",
    "spot/iso-0.25",
    "circle-2d/aniso-0.5",
    "network-3d/aniso-0.5",
    "cloud-sphere/aniso-0.5",
    "sphere-2.5K/outliers-0.25",
    "box/normal-0.1",
]

_SHARED: list[tuple[str, str, dict[str, Any]]] = [
    ("fandisk.obj", "obj", {}),
    ("bun_zipper_res4.ply", "ply", {}),
    ("spot.obj", "obj", {}),
    ("korita-zbevnica.gpx", "gpx", {}),
    ("ne_110m_coastline.geojson", "geojson", {}),
    ("featuretype.ply", "ply", {}),
    ("wrench.dxf", "dxf", {}),
    ("points_agisoft.xyz", "xyz", {}),
    ("bun000.ply", "ply", {}),
]

_EXTRA_PARAMS: list[tuple[str, str, dict[str, Any]]] = [
    ("fandisk.obj", "obj", {"rms": 0.01}),
    ("bun_zipper_res4.ply", "ply", {"rms": 0.0005, "preset": "report"}),
    (
        "bun_zipper_res4.ply",
        "ply",
        {"rms": 0.0005, "method": "windowed-sinc", "displacement": "free"},
    ),
    ("bun_zipper_res4.ply", "ply", {"tau": "gcv"}),
    ("bun_zipper_res4.ply", "ply", {"rms": 0.0005, "max_deviation": 0.001}),
    ("bun_zipper_res4.ply", "ply", {"rms": 0.0005, "preserve_volume": True}),
    ("bun_zipper_res4.ply", "ply", {"lam": 0.05}),
    ("bun_zipper_res4.ply", "ply", {"rms": 0.0005, "laplacian": "curvature"}),
    ("bun_zipper_res4.ply", "ply", {"rms": 0.0005, "laplacian": "feature"}),
    ("korita-zbevnica.gpx", "gpx", {"rms": 2.0}),
    ("points_agisoft.xyz", "xyz", {"rms": 0.02}),
    ("points_agisoft.xyz", "xyz", {"tile_points": 4000}),
    ("featuretype.ply", "ply", {"rms": 0.01}),
]


def _quick() -> Iterator[Golden]:
    for key in _QUICK_QUALITY:
        for mode, params in _QUALITY_MODES.items():
            yield Golden(f"quality/{key}/{mode}", _quality(key, params))
    yield Golden(
        "quality/sphere-2.5K/aniso-0.5/windowed-sinc",
        _quality(
            "sphere-2.5K/aniso-0.5",
            {"displacement": "free", "rms_sigma": True, "method": "windowed-sinc"},
        ),
    )
    yield Golden(
        "quality/cloud-sphere/aniso-0.5/tiles",
        _quality("cloud-sphere/aniso-0.5", {"tile_points": 1500}),
    )
    yield Golden(
        "quality/sphere-2.5K/aniso-0.5/tiles",
        _quality("sphere-2.5K/aniso-0.5", {"tile_points": 1000, "rms_sigma": True}),
    )
    for file, fmt, params in _SHARED:
        yield Golden(f"shared/{file}/default", _shared(file, params), fmt)
    for i, (file, fmt, params) in enumerate(_EXTRA_PARAMS):
        yield Golden(
            f"shared/{file}/p{i}:{json.dumps(params, sort_keys=True)}", _shared(file, params), fmt
        )
    for name in ("ico:3/medium/plain", "ico:3/heavy/fixed", "ico:3/light/weights"):
        if _speed_exists(name):
            yield Golden(f"speed/{name}", _speed(name))


def _speed_exists(name: str) -> bool:
    from benchmarks.speed.jobs import JOB_SETS

    return any(j.name == name for s in JOB_SETS.values() for j in s())


def _full() -> Iterator[Golden]:
    from benchmarks.quality.cases import FULL
    from benchmarks.quality.families import CASES
    from benchmarks.speed.jobs import JOB_SETS

    yield from _quick()
    for key in FULL:
        for mode in ("default", "report-rms"):
            yield Golden(f"full/{key}/{mode}", _quality(key, _QUALITY_MODES[mode]))
    for key in CASES:
        yield Golden(f"halves/{key}/default", _quality(key, {}))
    for job in JOB_SETS["counts"]():
        yield Golden(f"speed/{job.name}", _speed(job.name))


SETS: dict[str, Callable[[], Iterator[Golden]]] = {"quick": _quick, "full": _full}


def cases(name: str) -> list[Golden]:
    return list(SETS[name]())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.golden.cases")
    ap.add_argument("--set", choices=sorted(SETS), default="quick")
    ap.add_argument("--write", action="store_true", help="rewrite the committed hashes")
    ap.add_argument("--only", help="substring of the case names to run")
    args = ap.parse_args(argv)
    from service.core.linalg.threads import use_default_threads

    use_default_threads({})
    path = HASHES[args.set]
    known = json.loads(path.read_text()) if path.exists() else {}
    got: dict[str, dict[str, str]] = {}
    bad = 0
    for case in cases(args.set):
        if args.only and args.only not in case.name:
            continue
        got[case.name] = run_case(case)
        same = known.get(case.name) == got[case.name]
        bad += not same
        print(("same " if same else "DIFF ") + case.name, flush=True)
    print(f"{len(got) - bad} identical, {bad} different of {len(got)}")
    if args.write:
        path.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
    return 0 if bad == 0 or args.write else 1


if __name__ == "__main__":
    sys.exit(main())
