"""``smooth()``: the single entry point of the engine (exported as ``service.core.smooth``).

Pipeline (report sections 4-8): neighbourhoods -> weights and curvature -> Laplacian variant ->
elimination of fixed points -> one symbolic analysis -> for each lambda of the search of section
6.3 one numeric factorization and a solve of eq. (17) -> optional volume/area rescaling ->
diagnostics.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from service.core.curvature import curvature
from service.core.errors import ParameterError, TauOutOfRange
from service.core.geometry import Geometry
from service.core.laplacian import laplacian
from service.core.neighborhoods import (
    Neighborhoods,
    cloud_delaunay_neighborhoods,
    cloud_knn_neighborhoods,
    curve_neighborhoods,
    mesh_neighborhoods,
    unique_faces,
)
from service.core.params import SmoothingParams
from service.core.progress import ProgressCallback, ProgressEvent
from service.core.result import SmoothResult, Spectrum
from service.core.shrinkage import (
    enclosed_measure,
    is_closed_curve_set,
    is_closed_mesh,
    rescale_to_measure,
)
from service.core.solver import NormalEquations, split_fixed
from service.core.spectrum import SPECTRUM_MAX_POINTS, filter_factors, singular_values
from service.core.tau import initial_lambda, search_lambda
from service.core.weights import ResolvedScheme, neighbor_weights

__all__ = ["ProgressCallback", "build_laplacian", "resolve_weights", "smooth"]

def resolve_weights(params: SmoothingParams, geometry: Geometry) -> ResolvedScheme:
    """The weight scheme actually used: ``auto`` resolved as in the report.

    Reciprocal distance for curves (section 4.2) and k-NN neighbourhoods; mean value for meshes
    (4.3) and Delaunay neighbourhoods (4.4).

    Raises
    ------
    ParameterError
        For triangle-based weights without triangles (curves, k-NN neighbourhoods).
    """
    kind = geometry.kind
    triangles = kind == "mesh" or (kind == "cloud" and params.neighborhood == "delaunay")
    if params.weights == "auto":
        return "mean-value" if triangles else "reciprocal"
    if params.weights in ("mean-value", "cotangent") and not triangles:
        where = "a curve" if kind == "curve" else "k-NN neighbourhoods"
        raise ParameterError(
            f"weights '{params.weights}' need triangles, which {where} do not have: use "
            "'reciprocal' or 'uniform'"
            + (", or neighborhood 'delaunay'" if kind == "cloud" else ""),
            field="params.weights",
        )
    return params.weights


def _neighborhoods(geometry: Geometry, params: SmoothingParams) -> Neighborhoods:
    P = geometry.points
    if geometry.faces is not None:
        return mesh_neighborhoods(geometry.faces, geometry.n, geometry.edges)
    if geometry.edges is not None:
        return curve_neighborhoods(geometry.edges, geometry.n)
    if params.neighborhood == "delaunay":
        return cloud_delaunay_neighborhoods(P, params.k)
    return cloud_knn_neighborhoods(P, params.k)


def build_laplacian(
    geometry: Geometry, params: SmoothingParams
) -> tuple[sp.csr_matrix, Neighborhoods, ResolvedScheme, dict[str, float]]:
    """Neighbourhoods, weights, curvature and the Laplacian variant for ``geometry``.

    Parameters
    ----------
    geometry : Geometry
    params : SmoothingParams

    Returns
    -------
    L : scipy.sparse.csr_matrix, shape (n, n)
        ``L^(n)``, ``L^(kappa)`` or ``L^(f)`` (report section 4.1).
    nb : Neighborhoods
    scheme : str
        Resolved weight scheme.
    timings : dict
        Seconds for ``neighborhoods`` and ``laplacian``.
    """
    scheme = resolve_weights(params, geometry)
    P = geometry.points
    t0 = time.perf_counter()
    nb = _neighborhoods(geometry, params)
    curv_nb = nb
    if params.laplacian != "normalized" and nb.source == "knn":
        curv_nb = cloud_delaunay_neighborhoods(P, params.k)  # curvature from Delaunay fans
    t1 = time.perf_counter()
    W = neighbor_weights(P, nb, scheme)
    kappa = curvature(P, curv_nb) if params.laplacian != "normalized" else None
    L = laplacian(W, P, params.laplacian, kappa, params.sigma_h, params.sigma_f)
    t2 = time.perf_counter()
    return L, nb, scheme, {"neighborhoods": t1 - t0, "laplacian": t2 - t1}


def _phi_at_zero(
    L: sp.csr_matrix,
    P: NDArray[np.float64],
    omega: NDArray[np.float64],
    fixed: NDArray[np.bool_],
    free: NDArray[np.int64],
    M: sp.spmatrix,
    b: NDArray[np.float64],
    solver: str,
) -> tuple[float, NormalEquations | None]:
    """``phi(0)``: deviation of the limit ``lambda -> 0`` of eq. (4) (eqs. 13-14).

    Per connected component of the graph of ``L``: without fixed points the limit is the
    weighted centroid of eq. (14); with fixed points it is the minimizer of ``||L X||`` with the
    fixed points as boundary values, found by one extra (tiny-ridge) factorization.
    """
    n = P.shape[0]
    coo = L[free].tocoo()
    g = sp.csr_matrix((np.ones(coo.nnz), (free[coo.row], coo.col)), shape=(n, n))
    _, labels = connected_components(g, directed=False)
    w2 = omega**2
    has_fixed = np.zeros(labels.max() + 1, dtype=bool)
    has_fixed[labels[fixed]] = True
    lab_f = labels[free]
    plain = ~has_fixed[lab_f]
    phi0 = 0.0
    if plain.any():
        idx, lab = free[plain], lab_f[plain]
        sw = np.bincount(lab, weights=w2[idx], minlength=labels.max() + 1)
        cen = (
            np.stack(
                [
                    np.bincount(lab, weights=w2[idx] * P[idx, c], minlength=sw.size)
                    for c in range(P.shape[1])
                ],
                axis=1,
            )
            / np.maximum(sw, 1e-300)[:, None]
        )
        phi0 += float(np.sum(w2[idx, None] * (P[idx] - cen[lab]) ** 2))
    extra: NormalEquations | None = None
    if (~plain).any():
        sub = np.flatnonzero(~plain)
        Ms = sp.csc_matrix(M)[sub][:, sub]
        d2 = w2[free[sub]]
        extra = NormalEquations(Ms, d2, solver)  # type: ignore[arg-type]
        ridge = 1e-12 * initial_lambda(extra.M_fro, float(np.linalg.norm(d2)))
        X0 = extra.solve(ridge, b[sub] + ridge * d2[:, None] * P[free[sub]])
        phi0 += float(np.sum(d2[:, None] * (X0 - P[free[sub]]) ** 2))
    return phi0, extra


def smooth(
    geometry: Geometry, params: SmoothingParams, progress: ProgressCallback | None = None
) -> SmoothResult:
    """Smooth points, curves or meshes (report KU Leuven TW 451).

    Solves ``X* = argmin ||L X||_F^2 + lambda ||D (X - P)||_F^2`` (eq. 4) with ``L`` the chosen
    Laplacian variant (section 4), ``D`` the per-point weights, fixed points eliminated
    (infinite weights, section 8), and ``lambda`` either given or found such that
    ``phi(lambda) = ||D(X - P)||_F^2 = tau`` (eqs. 3, 15; section 6.3).

    Parameters
    ----------
    geometry : Geometry
        Validated input.
    params : SmoothingParams
        Exactly one of ``lam``, ``tau``, ``rms``; see the model for the other fields.
    progress : callable, optional
        ``progress(event)`` with a :class:`~service.core.progress.ProgressEvent`: once per
        stage, and once per lambda tried (stage ``search``). From the ``analysis`` stage on,
        ``event.tau`` is the resolved target (the one ``rms`` implies, over the free points).

    Returns
    -------
    SmoothResult

    Raises
    ------
    ParameterError
        Parameters that do not fit the geometry (e.g. triangle weights on a curve).
    TauOutOfRange
        ``tau`` (or the ``tau`` implied by ``rms``) outside ``(0, phi(0))``.
    SolverError
        The factorization failed.
    """
    t_start = time.perf_counter()

    def emit(stage: str, **kw: float | int | None) -> None:
        if progress is not None:
            progress(ProgressEvent(stage, elapsed=time.perf_counter() - t_start, **kw))  # type: ignore[arg-type]

    P = geometry.points
    n = geometry.n
    notes: list[str] = []
    emit("neighborhoods")
    L, nb, scheme, timings = build_laplacian(geometry, params)

    fixed = geometry.fixed_mask()
    if params.fix_boundary:
        if nb.source == "knn":
            notes.append("fix_boundary has no effect on k-NN neighbourhoods (no boundary defined)")
        fixed = fixed | nb.boundary
    if params.preserve_volume:
        _check_preservable(geometry, fixed)
    n_fixed = int(fixed.sum())
    # points without any coupling pass through bit-identical: eliminate them like fixed points
    coupled = (np.diff(L.indptr) > 0) | (np.bincount(L.indices, minlength=n) > 0)
    fixed = fixed | ~coupled
    omega = geometry.omega()
    L_F, L_C, free, fixed_idx = split_fixed(L, fixed)
    w2_free = omega[free] ** 2
    P_F = P[free]
    b = np.zeros_like(P_F)
    if fixed_idx.size and free.size:
        b = -np.asarray(L_F.T @ (L_C @ P[fixed_idx]))
    M = (L_F.T @ L_F).tocsc()
    M.eliminate_zeros()

    tau: float | None = None
    if params.lam is None:
        tau = params.tau if params.tau is not None else float(params.rms**2 * w2_free.sum())  # type: ignore[operator]
    field = "params.tau" if params.tau is not None else "params.rms"
    emit("analysis", tau=tau)

    if free.size == 0 or M.nnz == 0:
        if tau is not None:
            why = "every point is fixed" if free.size == 0 else "the Laplacian is zero"
            raise TauOutOfRange(
                f"nothing can move ({why}): no smoothing factor can be met; valid range is empty",
                field=field,
                tau=tau,
                tau_max=0.0,
            )
        return _result(
            geometry,
            params,
            P.copy(),
            float(params.lam or 0.0),
            0.0,
            None,
            True,
            [],
            0,
            timings,
            "none",
            scheme,
            n_fixed,
            [*notes, "nothing to smooth: the input is returned unchanged"],
            t_start,
        )

    t_an = time.perf_counter()
    eq = NormalEquations(M, w2_free, params.solver)
    notes.extend(eq.stats.warnings)
    state: dict[str, object] = {}

    def solve(lam: float) -> NDArray[np.float64]:
        X_F = eq.solve(lam, lam * w2_free[:, None] * P_F + b)
        state["lam"] = lam
        state["X_F"] = X_F
        return X_F

    def phi_of(lam: float) -> float:
        X_F = solve(lam)
        phi = float(np.sum(w2_free[:, None] * (X_F - P_F) ** 2))
        emit("search", tau=tau, iteration=len(history_calls) + 1, lam=lam, phi=phi)
        history_calls.append(lam)
        return phi

    history_calls: list[float] = []
    extra_eq: NormalEquations | None = None
    t_search = time.perf_counter()
    if params.lam is not None:
        lam = params.lam
        phi = phi_of(lam)
        history = [(lam, phi)]
        converged = True
    else:
        assert tau is not None
        phi0, extra_eq = _phi_at_zero(L, P, omega, fixed, free, M, b, params.solver)
        if not (0.0 < tau < phi0):
            raise TauOutOfRange(
                f"smoothing factor tau={tau:.6g} is out of range: it must lie in (0, {phi0:.6g}),"
                " where the upper bound phi(0) is the deviation of the fully smoothed shape",
                field=field,
                tau=tau,
                tau_max=phi0,
            )
        lam0 = initial_lambda(eq.M_fro, float(np.linalg.norm(w2_free)))
        search = search_lambda(phi_of, tau, phi0, lam0, params.tolerance, params.max_iterations)
        lam, phi, history, converged = search.lam, search.phi, search.history, search.converged
        if not converged:
            notes.append(
                f"the lambda search did not reach the tolerance in {search.iterations} iterations;"
                f" best relative error {abs(phi - tau) / tau:.3g}"
            )
        if state.get("lam") != lam:
            solve(lam)
    t_end_search = time.perf_counter()

    emit("postprocess", tau=tau, iteration=len(history_calls))
    X = P.copy()
    X[free] = state["X_F"]  # type: ignore[assignment]
    volume_scale = None
    if params.preserve_volume:
        X, volume_scale = _preserve(geometry, X)
    stats = eq.stats
    n_fact = stats.factorizations
    timings.update(
        analysis=stats.analysis,
        factorization=stats.factorization,
        solve=stats.solve,
        search=t_end_search - t_search,
    )
    if extra_eq is not None:
        n_fact += extra_eq.stats.factorizations
        timings["analysis"] += extra_eq.stats.analysis
        timings["factorization"] += extra_eq.stats.factorization
        timings["solve"] += extra_eq.stats.solve
    timings["setup"] = t_search - t_an - stats.analysis
    spectrum = None
    if params.spectrum:
        spectrum = _spectrum(L, omega, lam, fixed_idx.size, n, notes)
    return _result(
        geometry,
        params,
        X,
        lam,
        phi,
        tau,
        converged,
        history,
        n_fact,
        timings,
        eq.method,
        scheme,
        n_fixed,
        notes,
        t_start,
        volume_scale,
        spectrum,
    )


def _check_preservable(geometry: Geometry, fixed: NDArray[np.bool_]) -> None:
    ok = False
    if geometry.faces is not None:
        ok = geometry.dim == 3 and is_closed_mesh(unique_faces(geometry.faces))
    elif geometry.edges is not None:
        ok = geometry.dim == 2 and is_closed_curve_set(geometry.edges, geometry.n)
    if not ok:
        raise ParameterError(
            "preserve_volume needs a closed triangle mesh in 3D or closed polygons in 2D",
            field="params.preserve_volume",
        )
    if fixed.any():
        raise ParameterError(
            "preserve_volume cannot be combined with fixed points (rescaling would move them)",
            field="params.preserve_volume",
        )


def _preserve(geometry: Geometry, X: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    faces = unique_faces(geometry.faces) if geometry.faces is not None else None
    edges = geometry.edges if faces is None else None
    before = enclosed_measure(geometry.points, faces, edges)
    after = enclosed_measure(X, faces, edges)
    referenced = np.zeros(geometry.n, dtype=bool)
    referenced[(faces if faces is not None else edges).ravel()] = True  # type: ignore[union-attr]
    return rescale_to_measure(X, referenced, before, after, geometry.dim)


def _spectrum(
    L: sp.csr_matrix,
    omega: NDArray[np.float64],
    lam: float,
    n_fixed: int,
    n: int,
    notes: list[str],
) -> Spectrum | None:
    if n_fixed:
        notes.append("spectrum: not available with fixed points (eq. 12 assumes none)")
        return None
    if n > SPECTRUM_MAX_POINTS:
        notes.append(f"spectrum: only computed for inputs up to {SPECTRUM_MAX_POINTS} points")
        return None
    sigma, _ = singular_values(L, omega)
    return Spectrum(sigma=sigma, gamma=filter_factors(sigma, lam))


def _result(
    geometry: Geometry,
    params: SmoothingParams,
    X: NDArray[np.float64],
    lam: float,
    phi: float,
    tau: float | None,
    converged: bool,
    history: list[tuple[float, float]],
    factorizations: int,
    timings: dict[str, float],
    solver: str,
    scheme: str,
    n_fixed: int,
    notes: list[str],
    t_start: float,
    volume_scale: float | None = None,
    spectrum: Spectrum | None = None,
) -> SmoothResult:
    dev = np.linalg.norm(X - geometry.points, axis=1)
    timings = {k: float(v) for k, v in timings.items()}
    timings["total"] = time.perf_counter() - t_start
    return SmoothResult(
        points=X,
        lam=float(lam),
        phi=float(phi),
        tau=None if tau is None else float(tau),
        relative_error=None if tau is None else abs(phi - tau) / tau,
        converged=converged,
        iterations=len(history),
        factorizations=factorizations,
        history=[(float(a), float(b)) for a, b in history],
        deviation=dev,
        rms_deviation=float(np.sqrt(np.mean(dev**2))),
        max_deviation=float(dev.max()),
        timings=timings,
        solver=solver,
        laplacian=params.laplacian,
        weights=scheme,
        kind=geometry.kind,
        n_fixed=n_fixed,
        volume_scale=volume_scale,
        warnings=notes,
        spectrum=spectrum,
    )
