"""Peer smoothing filters against ours, on inputs with known ground truth (issue 5, part 2).

For every peer filter (trimesh, Open3D, PyMeshLab) a parameter sweep (iterations x lambda/mu)
is run; the setting with the smallest RMS distance to the ground truth is its "best" result.
Ours is then run at the tau equal to that result's deviation ``sum ||x - p||^2`` (same budget,
different filter), at ``tau`` = noise energy, and over a small tau sweep (its own "best").
"""

from __future__ import annotations

import importlib.metadata
import itertools
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks import metrics
from benchmarks.shapes import Case, peer_cases
from service.core import Geometry, SmoothingParams, smooth
from service.core.errors import GeosmoothError

__all__ = ["PEERS", "Peer", "available_peers", "run_case", "run_peers"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Filter = Callable[[FloatArray, IntArray, dict[str, Any]], FloatArray]


@dataclass
class Peer:
    """One peer filter and its parameter grid.

    Attributes
    ----------
    name : str
        Table label.
    package : str
        Distribution that provides it.
    run : callable
        ``run(V, F, setting) -> new vertices`` (mesh only; the input is not modified).
    grid : callable
        ``grid(quick) -> iterable of settings``.
    """

    name: str
    package: str
    run: Filter
    grid: Callable[[bool], Iterable[dict[str, Any]]]


ITERS = (1, 2, 3, 5, 8, 13, 21, 34, 55, 89)
ITERS_QUICK = (1, 2, 4, 8, 16, 32)
TAUBIN_ITERS = (*ITERS, 144)


def _iters(quick: bool, taubin: bool = False) -> tuple[int, ...]:
    if quick:
        return ITERS_QUICK
    return TAUBIN_ITERS if taubin else ITERS


def _mu(lam: float, k_pb: float = 0.1) -> float:
    """Taubin's mu from lambda and the pass-band frequency ``k_PB = 1/lambda + 1/mu``."""
    return 1.0 / (k_pb - 1.0 / lam)


# --- trimesh ---------------------------------------------------------------------------------


def _trimesh(V: FloatArray, F: IntArray) -> Any:
    import trimesh

    return trimesh.Trimesh(vertices=V.copy(), faces=F, process=False)


def _tm_laplacian(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    from trimesh.smoothing import filter_laplacian

    m = filter_laplacian(
        _trimesh(V, F),
        lamb=s["lambda"],
        iterations=s["iterations"],
        volume_constraint=s["volume_constraint"],
    )
    return np.asarray(m.vertices)


def _tm_taubin(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    from trimesh.smoothing import filter_taubin

    # trimesh counts half-steps (a shrink or an inflate step) as iterations
    m = filter_taubin(_trimesh(V, F), lamb=s["lambda"], nu=-s["mu"], iterations=2 * s["iterations"])
    return np.asarray(m.vertices)


def _tm_humphrey(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    from trimesh.smoothing import filter_humphrey

    m = filter_humphrey(
        _trimesh(V, F), alpha=s["alpha"], beta=s["beta"], iterations=s["iterations"]
    )
    return np.asarray(m.vertices)


# --- Open3D ----------------------------------------------------------------------------------


def _o3d(V: FloatArray, F: IntArray) -> Any:
    import open3d as o3d

    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
    )


def _o3d_laplacian(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    m = _o3d(V, F).filter_smooth_laplacian(
        number_of_iterations=s["iterations"], lambda_filter=s["lambda"]
    )
    return np.asarray(m.vertices)


def _o3d_taubin(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    m = _o3d(V, F).filter_smooth_taubin(
        number_of_iterations=s["iterations"], lambda_filter=s["lambda"], mu=s["mu"]
    )
    return np.asarray(m.vertices)


# --- PyMeshLab -------------------------------------------------------------------------------


def _meshlab(V: FloatArray, F: IntArray, apply: Callable[[Any], None]) -> FloatArray:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
    apply(ms)
    out = np.asarray(ms.current_mesh().vertex_matrix(), dtype=np.float64)
    if out.shape != V.shape:
        raise RuntimeError(f"PyMeshLab changed the vertex count ({V.shape} -> {out.shape})")
    return out


def _ml_laplacian(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    return _meshlab(
        V,
        F,
        lambda ms: ms.apply_coord_laplacian_smoothing(
            stepsmoothnum=s["iterations"], cotangentweight=s["cotangent"]
        ),
    )


def _ml_taubin(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    return _meshlab(
        V,
        F,
        lambda ms: ms.apply_coord_taubin_smoothing(
            lambda_=s["lambda"], mu=s["mu"], stepsmoothnum=s["iterations"]
        ),
    )


def _ml_two_step(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    return _meshlab(
        V,
        F,
        lambda ms: ms.apply_coord_two_steps_smoothing(
            stepsmoothnum=s["iterations"], normalthr=s["normalthr"]
        ),
    )


def _ml_hc(V: FloatArray, F: IntArray, s: dict[str, Any]) -> FloatArray:
    def apply(ms: Any) -> None:
        for _ in range(s["iterations"]):
            ms.apply_coord_hc_laplacian_smoothing()

    return _meshlab(V, F, apply)


# --- grids -----------------------------------------------------------------------------------


def _grid(**axes: Iterable[Any]) -> list[dict[str, Any]]:
    keys = list(axes)
    return [dict(zip(keys, vals, strict=True)) for vals in itertools.product(*axes.values())]


def _lap_grid(quick: bool) -> list[dict[str, Any]]:
    return _grid(iterations=_iters(quick), **{"lambda": (0.5,) if quick else (0.2, 0.5, 0.9)})


def _taubin_grid(quick: bool) -> list[dict[str, Any]]:
    lams = (0.5,) if quick else (0.3, 0.5, 0.7)
    return [
        {"iterations": k, "lambda": lam, "mu": round(_mu(lam), 4)}
        for k in _iters(quick, taubin=True)
        for lam in lams
    ]


PEERS: list[Peer] = [
    Peer(
        "trimesh filter_laplacian",
        "trimesh",
        _tm_laplacian,
        lambda q: [{**s, "volume_constraint": vc} for s in _lap_grid(q) for vc in (True, False)],
    ),
    Peer("trimesh filter_taubin", "trimesh", _tm_taubin, _taubin_grid),
    Peer(
        "trimesh filter_humphrey",
        "trimesh",
        _tm_humphrey,
        lambda q: _grid(iterations=_iters(q), alpha=(0.1,), beta=(0.5,) if q else (0.2, 0.5, 0.8)),
    ),
    Peer("Open3D filter_smooth_laplacian", "open3d", _o3d_laplacian, _lap_grid),
    Peer("Open3D filter_smooth_taubin", "open3d", _o3d_taubin, _taubin_grid),
    Peer(
        "PyMeshLab Laplacian",
        "pymeshlab",
        _ml_laplacian,
        lambda q: _grid(iterations=_iters(q), cotangent=(True, False)),
    ),
    Peer("PyMeshLab Taubin", "pymeshlab", _ml_taubin, _taubin_grid),
    Peer(
        "PyMeshLab two-step",
        "pymeshlab",
        _ml_two_step,
        lambda q: _grid(iterations=_iters(q)[:6], normalthr=(60,) if q else (20, 40, 60)),
    ),
    Peer(
        "PyMeshLab HC Laplacian",
        "pymeshlab",
        _ml_hc,
        lambda q: _grid(iterations=(1, 2, 4) if q else (1, 2, 3, 5, 8)),
    ),
]


def available_peers() -> dict[str, dict[str, Any]]:
    """Which peer packages import here: ``{package: {"version": ..., "error": ...}}``."""
    out: dict[str, dict[str, Any]] = {}
    for pkg, mod in (("trimesh", "trimesh"), ("open3d", "open3d"), ("pymeshlab", "pymeshlab")):
        try:
            __import__(mod)
            out[pkg] = {"version": importlib.metadata.version(pkg), "error": None}
        except Exception as exc:  # ImportError, or a missing system library (OSError)
            out[pkg] = {"version": None, "error": f"{type(exc).__name__}: {exc}"}
    return out


# --- evaluation ------------------------------------------------------------------------------


@dataclass
class Outcome:
    """One method on one case, at its chosen setting."""

    method: str
    setting: str
    error: float | None = None
    time: float | None = None
    volume_change: float | None = None
    deviation: float | None = None
    tau: float | None = None
    note: str = ""
    ours_same_tau: dict[str, Any] | None = None
    settings_tried: int = 0
    sweep_seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _setting_str(s: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in s.items())


class _Scorer:
    """RMS error to the ground truth, on a fixed subsample during sweeps of large inputs."""

    def __init__(self, case: Case, max_points: int = 6000) -> None:
        assert case.truth is not None
        self.truth = case.truth
        n = case.n
        self.sub = (
            np.sort(np.random.default_rng(0).choice(n, max_points, replace=False))
            if n > max_points
            else None
        )

    def quick(self, X: FloatArray) -> float:
        return metrics.rms(self.truth(X if self.sub is None else X[self.sub]))

    def full(self, X: FloatArray) -> float:
        return metrics.rms(self.truth(X))


def _volume(case: Case, X: FloatArray) -> float | None:
    if not case.closed:
        return None
    return metrics.measure_change(X, case.points, case.faces, case.edges)


def _ours(case: Case, scorer: _Scorer, **params: Any) -> dict[str, Any]:
    geom = Geometry(case.points, faces=case.faces, edges=case.edges)
    try:
        res = smooth(geom, SmoothingParams(**params))
    except GeosmoothError as exc:
        return {"error": None, "note": exc.message}
    X = res.points
    return {
        "error": scorer.full(X),
        "time": res.timings["total"],
        "volume_change": _volume(case, X),
        "deviation": metrics.rms_deviation(X, case.points),
        "tau": res.tau,
        "iterations": res.iterations,
        "lam": res.lam,
        "note": "" if res.converged else "search not converged",
    }


def _run_peer(case: Case, peer: Peer, scorer: _Scorer, quick: bool) -> Outcome:
    assert case.faces is not None
    best: tuple[float, dict[str, Any], FloatArray, float] | None = None
    tried = 0
    t_sweep = time.perf_counter()
    for setting in peer.grid(quick):
        tried += 1
        t0 = time.perf_counter()
        X = peer.run(case.points, case.faces, setting)
        elapsed = time.perf_counter() - t0
        if not np.all(np.isfinite(X)):
            continue
        err = scorer.quick(X)
        if best is None or err < best[0]:
            best = (err, setting, X, elapsed)
    if best is None:
        return Outcome(peer.name, "—", note="no finite result", settings_tried=tried)
    _, setting, X, elapsed = best
    tau = float(np.sum((X - case.points) ** 2))
    return Outcome(
        method=peer.name,
        setting=_setting_str(setting),
        error=scorer.full(X),
        time=elapsed,
        volume_change=_volume(case, X),
        deviation=metrics.rms_deviation(X, case.points),
        tau=tau,
        settings_tried=tried,
        sweep_seconds=time.perf_counter() - t_sweep,
    )


TAU_FACTORS = (0.1, 0.2, 0.33, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0)
TAU_FACTORS_QUICK = (0.2, 0.33, 0.5, 1.0)
LARGE = 20000  # inputs above this many points get the quick sweep grid


def run_case(
    case: Case, quick: bool, installed: dict[str, dict[str, Any]], log: Callable[[str], None]
) -> dict[str, Any]:
    """All peers and our variants on one case."""
    scorer = _Scorer(case)
    rows: list[Outcome] = [
        Outcome(
            "noisy input",
            "—",
            error=scorer.full(case.points),
            time=0.0,
            volume_change=0.0 if case.closed else None,
            deviation=0.0,
        )
    ]
    for peer in PEERS:
        if case.kind != "mesh":
            rows.append(Outcome(peer.name, "n/a", note=f"no {case.kind} smoothing"))
            continue
        if installed[peer.package]["error"]:
            rows.append(Outcome(peer.name, "not installed", note=installed[peer.package]["error"]))
            continue
        t0 = time.perf_counter()
        try:
            out = _run_peer(case, peer, scorer, quick or case.n > LARGE)
        except Exception as exc:  # a peer failing on an input is a result, not a crash
            out = Outcome(peer.name, "failed", note=f"{type(exc).__name__}: {exc}")
        if out.tau is not None:
            out.ours_same_tau = _ours(case, scorer, tau=out.tau)
        rows.append(out)
        log(f"    {peer.name}: {time.perf_counter() - t0:.1f} s")

    def ours_row(label: str, **params: Any) -> Outcome:
        r = _ours(case, scorer, **params)
        return Outcome(
            label,
            _setting_str({k: v for k, v in params.items() if k != "tau"}) or "defaults",
            error=r.get("error"),
            time=r.get("time"),
            volume_change=r.get("volume_change"),
            deviation=r.get("deviation"),
            tau=r.get("tau"),
            note=r.get("note", ""),
        )

    tau = case.tau_noise
    rows.append(ours_row("ours, tau = noise energy", tau=tau))
    if case.sigma is not None:
        rows.append(ours_row("ours, tau = normal noise n*sigma^2", tau=tau / case.points.shape[1]))
    if case.kind == "mesh":
        rows.append(ours_row("ours, tau = noise energy", tau=tau, weights="uniform"))
    if case.closed:
        rows.append(ours_row("ours, tau = noise energy", tau=tau, preserve_volume=True))
        rows.append(
            ours_row(
                "ours, tau = normal noise n*sigma^2",
                tau=tau / case.points.shape[1],
                preserve_volume=True,
            )
        )
    if case.name == "box":
        rows.append(ours_row("ours, tau = noise energy", tau=tau, laplacian="feature"))
        rows.append(
            ours_row("ours, tau = normal noise n*sigma^2", tau=tau / 3, laplacian="feature")
        )
    t0 = time.perf_counter()
    best: Outcome | None = None
    for f in TAU_FACTORS_QUICK if quick else TAU_FACTORS:
        r = ours_row(f"ours, best tau (sweep {f:g} x noise)", tau=f * tau)
        if r.error is not None and (best is None or r.error < best.error):  # type: ignore[operator]
            best = r
    if best is not None:
        best.method = "ours, best tau of sweep"
        best.setting = f"tau = {best.tau / tau:g} x noise energy"  # type: ignore[operator]
        rows.append(best)
    log(f"    ours: {time.perf_counter() - t0:.1f} s (tau sweep)")
    return {
        "case": case.name,
        "n": case.n,
        "kind": case.kind,
        "source": case.source,
        "sigma": case.sigma,
        "tau_noise": tau,
        "closed": case.closed,
        "peer_grid": "quick" if quick else ("reduced (n > 20,000)" if case.n > LARGE else "full"),
        "rows": [r.to_dict() for r in rows],
    }


def run_peers(quick: bool, log: Callable[[str], None] = print) -> dict[str, Any]:
    """The whole peer comparison; returns the JSON-ready results."""
    installed = available_peers()
    cases = []
    t0 = time.perf_counter()
    for case in peer_cases(quick):
        log(f"  peers: {case.name} (n={case.n})")
        cases.append(run_case(case, quick, installed, log))
    return {"installed": installed, "cases": cases, "seconds": time.perf_counter() - t0}
