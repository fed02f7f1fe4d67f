"""Issue 31's scores of one result and its targets (:mod:`benchmarks.quality.issue31`).

Scores (:class:`Issue31Scorer`), on the *bulk* (the points the truth does not mark as outliers
or strays; every point for the other noise models):

* ``vertex`` / ``surface``: RMS distance to the clean positions / to the true surface, as
  fractions of the noisy input's (``None`` on a noise-free input);
* ``moved_h``: RMS move of all points from the input, in spacings ``h``;
* ``stray_max_h`` / ``stray_median_h``: how far the stray points moved (in ``h``);
* ``measure_pct``: surface area (meshes) or length (curves) against the clean shape's, percent;
* ``flipped``: faces turned over against the clean mesh.

Flags of the default's report (:func:`flags`) and the issue's targets per case
(:func:`checks`): never worse than the input; a clean input moved at most
:data:`CLEAN_MOVE` h (RMS); a noisy input (true sigma >= 0.1 h) smoothed; distance to the
surface within :data:`TAUBIN_FACTOR` of the better of Taubin x10 and x50; sigma^ within
:data:`SIGMA_TOL`; no stray point moved more than :data:`STRAY_SIGMAS` sigma^; no false warning
(a warning on a clean input other than "no noise found", "flattened" on a result whose area
or length is still at least the clean shape's, an outlier count on an input without outliers,
per-point noise weights on noise of one level everywhere).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks.quality.cases import Case
from benchmarks.quality.scores import face_normals, flipped_faces

__all__ = ["CLEAN_MOVE", "SIGMA_TOL", "STRAY_SIGMAS", "TAUBIN_FACTOR", "Issue31Scorer", "checks",
           "flags"]

FloatArray = NDArray[np.float64]
CLEAN_MOVE = 0.05
SIGMA_TOL = 0.15
STRAY_SIGMAS = 3.0
TAUBIN_FACTOR = 1.15
SMOOTHED_LEVEL = 0.1
#: noise models whose level varies across the input (none of issue 31's families)
VARYING = ("vary",)


class Issue31Scorer:
    """Scores results on one case against its truth (bulk only; strays apart)."""

    def __init__(self, case: Case) -> None:
        self.case = case
        self.truth = case.shape.points
        self.strays = case.outliers
        self.bulk = ~case.outliers
        self.v_in, self.s_in = self._errors(case.points)
        self.measure0 = self._measure(self.truth)

    def _errors(self, X: FloatArray) -> tuple[float, float]:
        b = self.bulk
        v = float(np.sqrt(np.mean(np.sum((X[b] - self.truth[b]) ** 2, axis=1))))
        s = float(np.sqrt(np.mean(self.case.shape.distance(X[b]) ** 2)))
        return v, s

    def _measure(self, X: FloatArray) -> float | None:
        shape = self.case.shape
        if shape.faces is not None:
            return float(np.linalg.norm(face_normals(X, shape.faces), axis=1).sum() / 2)
        if shape.edges is not None:
            return float(np.linalg.norm(X[shape.edges[:, 1]] - X[shape.edges[:, 0]], axis=1).sum())
        return None

    def score(self, X: FloatArray) -> dict[str, Any]:
        """The scores of the module docstring for result ``X``."""
        h = self.case.shape.h
        v, s = self._errors(X)
        moves = np.linalg.norm(X - self.case.points, axis=1)
        m = self._measure(X)
        out: dict[str, Any] = {
            "vertex": v / self.v_in if self.v_in > 0 else None,
            "surface": s / self.s_in if self.s_in > 0 else None,
            "vertex_h": v / h, "surface_h": s / h,
            "moved_h": float(np.sqrt(np.mean(moves**2))) / h,
            "stray_max_h": float(moves[self.strays].max()) / h if self.strays.any() else None,
            "stray_median_h": (float(np.median(moves[self.strays])) / h
                               if self.strays.any() else None),
            "measure_pct": (100.0 * (m - self.measure0) / self.measure0
                            if m is not None and self.measure0 else None),
            "flipped": None,
        }
        if self.case.shape.faces is not None:
            out["flipped"] = flipped_faces(X, self.truth, self.case.shape.faces)
        return out


def flags(report: dict[str, Any]) -> dict[str, Any]:
    """What the default's report says: noise weights, outliers, flattened, moved-too-far,
    no noise found, every warning."""
    warnings = list(report.get("warnings") or [])
    return {
        "noise_weights": any(w.startswith("noise varies") for w in warnings),
        "outliers": int(report.get("outlier_count") or 0),
        "flattened": any("flattened" in w for w in warnings),
        "moved_far": any("more than removing the noise explains" in w for w in warnings),
        "no_noise": report.get("noise_found") is False,
        "warnings": warnings,
    }


def checks(case: Case, auto: dict[str, Any], taubin: dict[str, dict[str, Any]],
           sigma_hat: float | None, flag: dict[str, Any]) -> dict[str, Any]:
    """The issue's targets on one case: ``True`` met, ``False`` missed, ``None`` not applicable;
    plus the false warnings found (a list of short names)."""
    clean = case.noise == "clean"
    h = case.shape.h
    out: dict[str, Any] = {}
    out["not_worse"] = None if clean else bool(auto["vertex"] <= 1.0 and auto["surface"] <= 1.0)
    out["clean_still"] = bool(auto["moved_h"] <= CLEAN_MOVE) if clean else None
    out["smoothed"] = (bool(not flag["no_noise"] and auto["surface"] < 1.0)
                       if not clean and case.sigma >= SMOOTHED_LEVEL * h else None)
    best = min((t["surface"] for t in taubin.values() if t and t.get("surface") is not None),
               default=None)
    out["taubin_ratio"] = auto["surface"] / best if best and auto["surface"] is not None else None
    out["vs_taubin"] = (None if out["taubin_ratio"] is None
                        else bool(out["taubin_ratio"] <= TAUBIN_FACTOR))
    out["sigma_ratio"] = sigma_hat / case.sigma if sigma_hat is not None and case.sigma else None
    out["sigma_ok"] = (None if out["sigma_ratio"] is None
                       else bool(abs(out["sigma_ratio"] - 1.0) <= SIGMA_TOL))
    if auto["stray_max_h"] is not None:
        out["stray_sigmas"] = (auto["stray_max_h"] * h / sigma_hat if sigma_hat
                               else float("inf"))
        out["strays_ok"] = bool(out["stray_sigmas"] <= STRAY_SIGMAS)
    else:
        out["stray_sigmas"], out["strays_ok"] = None, None
    false: list[str] = []
    if clean and [w for w in flag["warnings"] if "no noise found" not in w]:
        false.append("warning on clean input")  # "no noise found: returned unchanged" is right
    if flag["flattened"] and auto["measure_pct"] is not None and auto["measure_pct"] >= 0.0:
        false.append("flattened but under-smoothed")
    if flag["outliers"] and not case.outliers.any():
        false.append("outliers on outlier-free noise")
    if flag["noise_weights"] and case.noise not in VARYING:
        false.append("noise weights on uniform noise")
    out["false_warnings"] = false
    return out
