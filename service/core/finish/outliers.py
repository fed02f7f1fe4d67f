"""Outliers after the solve (issue 31): kept in place (flag, drop) or pulled in, bounded.

The robust data weights (:mod:`service.core.noise.robust`) give an outlier (next to) no weight,
so eq. (4) leaves it where the smoothness term alone wants it. What the output does with it is
``params.outliers`` (decided per kind in :mod:`service.core.plan`):

* ``"flag"`` and ``"drop"``: the point keeps its exact input position (bit for bit); the report
  lists it, the writers flag it (LAS classification 7, a PLY/PCD ``outlier`` attribute) or the
  workflow removes its row (``drop``). A cloud's stray point is usually not a noisy sample of the
  surface: relocating it by metres invents a surface point.
* ``"pull"``: :func:`pull_in` (``argmin ||L X||^2`` over the
  outliers), then each pulled point is clipped to its ring's reach: no further from its
  neighbours' centroid than the farthest neighbour (:func:`bound_to_ring`), and moved no
  further than it was from that centroid in the input (:func:`within_offset`).

A pulled point is reported as an outlier only when its move is more than the noise and the
smoothing explain (:func:`beyond_noise`, issue 31 item 4): on a scanned mesh with Gaussian
noise the residual test flags points of fine detail (the horse at 0.05 - 0.5 edge of noise:
42 - 3 points) whose moves stay within the other points' (largest 14.9 against 26.4 times the
estimated noise at 0.05 edge); spikes of 10 edges move 200 - 300 times it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import spsolve

from service.core.warnings import EngineWarning, warning

__all__ = [
    "EXTREME_ALPHA",
    "FAR_MOVE",
    "Outliers",
    "beyond_noise",
    "bound_to_ring",
    "far_moved",
    "outliers_of",
    "place_outliers",
    "within_offset",
]

#: After the solve, a cloud point the solution moved more than this many ``sigma sqrt(c)`` is
#: one the surface does not pass near (twice the Gaussian extreme ``z0`` of the outlier test,
#: as :func:`service.core.noise.robust.isolated`): a stray the residual test left undecided
#: (its neighbours are strays too). Only where that test found outliers already.
FAR_MOVE = 2.0 * 3.89

#: A move is beyond the noise's Gaussian extreme when a sample of ``n`` points' moves, all
#: Gaussian noise of the estimated ``sigma`` per coordinate, exceeds it with this probability.
EXTREME_ALPHA = 1e-3

Array = NDArray[np.float64]
Index = NDArray[np.int64]


def _none() -> Index:
    return np.zeros(0, np.int64)


@dataclass(frozen=True)
class Outliers:
    """The outliers of a run as the finish stage leaves them: the one record the plan's
    ``outliers`` entry and the report read (issue 38: they counted apart before).

    Attributes
    ----------
    mode : str
        ``"flag"``, ``"drop"`` or ``"pull"`` (the plan's).
    rule : str
        The robust rule the data weights applied.
    found : int
        Outliers the data weights found (a track's held corners are shape, not outliers).
    indices : ndarray of int
        The outliers reported (sorted): with ``flag``/``drop`` those found and the points the
        solve moved far (:func:`far_moved`); with ``pull`` those whose move is beyond what the
        noise and the smoothing explain (:func:`beyond_noise`).
    pulled : ndarray of int
        Reported outliers placed by :func:`pull_in` (next to no weight).
    far : int
        Points the solve moved far, kept in place as outliers too (``flag``/``drop``).
    within_noise : int
        Found outliers a ``pull`` moved no further than the noise explains (not reported).
    """

    mode: str
    rule: str = "none"
    found: int = 0
    indices: Index = field(default_factory=_none)
    pulled: Index = field(default_factory=_none)
    far: int = 0
    within_noise: int = 0

    @property
    def count(self) -> int:
        """The report's ``outlier_count``."""
        return int(self.indices.size)

    @property
    def warnings(self) -> tuple[EngineWarning, ...]:
        """What the user is told: the outliers and what happened to them (never tau advice)."""
        said = []
        shown = self.count if self.mode == "pull" else self.found
        if shown:
            said.append(warning("outliers", _outlier_message(shown, self.mode, self.rule),
                                count=shown, mode=self.mode, rule=self.rule))  # fmt: skip
        if self.far:
            said.append(warning(
                "outliers-moved-far",
                f"{self.far} more points the solve moved far from their input (beyond twice the "
                "outliers' threshold) were kept in place as outliers too",
                count=self.far, factor=FAR_MOVE,
            ))  # fmt: skip
        return tuple(said)


def _outlier_message(count: int, mode: str, rule: str) -> str:
    if mode == "flag":
        return (f"{count} points far from the surface flagged as outliers ({rule} weights): "
                "kept at their input positions and left out of tau; listed in the report "
                "(outliers) and flagged in the output where the format holds a flag (LAS "
                "classification 7, PLY/PCD vertex attribute 'outlier'); outliers='drop' "
                "removes them")
    if mode == "drop":
        return (f"{count} points far from the surface dropped as outliers ({rule} weights): "
                "the output is written without them; their indices are in the report "
                "(outliers)")
    return (f"{count} points far from the surface treated as outliers ({rule} weights): "
            "pulled back into their neighbours' ring")


def outliers_of(
    P: Array,
    X: Array,
    found: Index,
    pulled: Index,
    mode: str,
    rule: str,
    sigma: float | None,
    codim: int,
    kept: Index | None = None,
) -> Outliers:
    """The :class:`Outliers` of the final points ``X`` (input ``P``): ``found`` by the data
    weights (``pulled`` of them with next to no weight), ``kept`` in place by the finish stage
    (``flag``/``drop``: ``found`` and the points moved far), the noise level ``sigma`` in each
    of ``codim`` normal directions."""
    if mode != "pull":
        kept = found if kept is None else kept
        return Outliers(mode, rule, int(found.size), kept, pulled, int(kept.size - found.size))
    shown = beyond_noise(P, X, found, sigma, codim) if found.size else found
    return Outliers(mode, rule, int(found.size), shown, np.intersect1d(pulled, shown),
                    within_noise=int(found.size - shown.size))  # fmt: skip


def place_outliers(P: Array, X: Array, L: sp.spmatrix, idx: NDArray[np.int64], mode: str) -> Array:
    """``X`` with the outliers ``idx`` placed by ``mode`` (module docstring); ``P`` the input."""
    if idx.size == 0:
        return X
    if mode in ("flag", "drop"):
        out = X.copy()
        out[idx] = P[idx]
        return out
    return within_offset(P, bound_to_ring(pull_in(X, L, idx), L, idx), L, idx)


def within_offset(P: Array, X: Array, L: sp.spmatrix, idx: NDArray[np.int64]) -> Array:
    """``X`` with each pulled point of ``idx`` moved at most as far as it was, in the input,
    from its graph neighbours' centroid (issue 40): a point thrown off its ring comes back,
    while one at its ring's centre stays (a cylinder cap's hub of valence 200, flagged by the
    fit of its rim, was pulled 100 times the noise along the axis by the uniform Laplacian)."""
    S = abs(sp.csr_matrix(L, copy=True))
    S = sp.csr_matrix(S + S.T)
    out = X.copy()
    for i in idx:
        row = S.indices[S.indptr[i] : S.indptr[i + 1]]
        row = row[row != i]
        if row.size == 0:
            continue
        reach = float(np.linalg.norm(P[i] - P[row].mean(axis=0)))
        move = X[i] - P[i]
        dist = float(np.linalg.norm(move))
        if dist > reach:
            out[i] = P[i] + move * (reach / dist)
    return out


def far_moved(
    P: Array,
    X: Array,
    known: NDArray[np.int64],
    sigma: float | None,
    codim: int,
    scale: Array | None = None,
) -> NDArray[np.int64]:
    """``known`` with the points ``X`` moved more than :data:`FAR_MOVE` ``sigma_i sqrt(codim)``
    from ``P`` added (sorted; ``sigma_i = sigma scale_i``, the per-point noise level where the
    noise varies); ``known`` alone without a noise level or known outliers."""
    if not sigma or known.size == 0:
        return known
    moved = np.linalg.norm(X - P, axis=1)
    level = sigma * (1.0 if scale is None else scale)
    far = np.flatnonzero(moved > FAR_MOVE * level * np.sqrt(max(codim, 1)))
    return np.union1d(known, far).astype(np.int64)


def beyond_noise(
    P: Array, X: Array, idx: NDArray[np.int64], sigma: float | None, codim: int
) -> NDArray[np.int64]:
    """The points of ``idx`` that moved (``|X_i - P_i|``) further than both the Gaussian
    extreme of ``n`` moves of noise ``sigma`` in each of ``codim`` normal directions
    (``sigma^2 chi^2_codim``, probability :data:`EXTREME_ALPHA` for the largest of ``n``; the
    residual test's ``chi_c``) and every point not in ``idx``: moves the noise does not explain
    and the smoothing of the shape does not either. All of ``idx`` without a noise level."""
    from scipy.stats import chi2

    if idx.size == 0 or not sigma or idx.size >= P.shape[0]:
        return idx
    moved = np.linalg.norm(X - P, axis=1)
    rest = np.ones(P.shape[0], dtype=bool)
    rest[idx] = False
    extreme = sigma * float(np.sqrt(chi2.isf(EXTREME_ALPHA / P.shape[0], max(codim, 1))))
    return idx[moved[idx] > max(extreme, float(moved[rest].max()))]


def bound_to_ring(X: Array, L: sp.spmatrix, idx: NDArray[np.int64]) -> Array:
    """``X`` with each point of ``idx`` moved, if needed, onto the ball about its neighbours'
    centroid whose radius is the farthest neighbour's distance from it (its ring's reach).

    Neighbours are the other points of its row and column of ``L`` that are not outliers
    themselves (all of them when every neighbour is one); a point without any is left alone.
    """
    S = sp.csr_matrix(abs(sp.csr_matrix(L)) + abs(sp.csr_matrix(L)).T)
    outlier = np.zeros(X.shape[0], dtype=bool)
    outlier[idx] = True
    out = X.copy()
    for i in idx:
        row = S.indices[S.indptr[i] : S.indptr[i + 1]]
        row = row[row != i]
        keep = row[~outlier[row]]
        nbrs = keep if keep.size else row
        if nbrs.size == 0:
            continue
        Q = X[nbrs]
        c = Q.mean(axis=0)
        reach = float(np.max(np.linalg.norm(Q - c, axis=1)))
        off = X[i] - c
        dist = float(np.linalg.norm(off))
        if dist > reach:
            out[i] = c + off * (reach / dist)
    return out


def pull_in(X: Array, L: sp.spmatrix, idx: NDArray[np.int64]) -> Array:
    """``X`` with the points ``idx`` moved to ``argmin ||L X||_F^2`` over them, the others held.

    Eq. (4) with ``omega_i -> 0`` at these points: their data term vanishes, so whatever the
    displacement mode of the rest, the minimiser places them where the smoothness term alone
    wants them (``L_O^T L_O X_O = -L_O^T L_R X_R``; a point moving along its normal only
    could not come back from far along the surface or from inside a closed shape).
    """
    if idx.size == 0:
        return X
    L = sp.csc_matrix(L)
    rest = np.setdiff1d(np.arange(X.shape[0]), idx)
    Lo, Lr = L[:, idx], L[:, rest]
    A = sp.csc_matrix(Lo.T @ Lo)
    b = -(Lo.T @ (Lr @ X[rest]))
    ridge = 1e-10 * max(float(A.diagonal().max()), 1e-300)
    A = A + ridge * sp.identity(idx.size, format="csc")
    b = b + ridge * X[idx]
    out = X.copy()
    out[idx] = np.asarray(spsolve(A, b)).reshape(idx.size, -1)
    return out
