"""Krylov methods on the scaled normal equations ``(M_t + lambda I) y = c``.

With ``K(lambda) = M + lambda D^2`` (report eq. 17), ``M_t = D^-1 M D^-1``, ``y = D e`` and
``c = D^-1 r``, every deviation the engine needs is a function of ``M_t`` applied to ``c``:
``phi(lambda) = sum_i c_i^2 mu_i^(2k-2) / (mu_i + lambda)^(2k)`` over the eigenpairs ``mu_i`` of
``M_t`` (eq. 15 for iterated Tikhonov of order ``k``; ``k = 1`` is eq. 4).

* :func:`lanczos` runs the Lanczos recurrence on ``M_t`` from ``c`` (one product with ``M`` per
  step for all coordinate columns at once) and :class:`Quadrature` turns it into the Gauss
  quadrature model ``phi_j(lambda) = ||c||^2 e_1^T f(T_j) e_1`` (Golub and Meurant), a cheap
  lambda estimate before any factorization (no reorthogonalization: the quadrature stays
  accurate when orthogonality is lost, Golub and Strakos 1994).
* :func:`pcg` is the block (column-wise) preconditioned conjugate gradient used both by the
  matrix-free path (Jacobi preconditioner) and to reuse a factorization at a nearby lambda
  (the factor of ``K(lambda_0)`` as preconditioner: the spectrum of the preconditioned matrix
  lies in ``[min(1, lambda/lambda_0), max(1, lambda/lambda_0)]``). It stops on a rigorous
  bound: the smallest eigenvalue of ``M_t + lambda I`` is at least ``lambda``, so
  ``||D (x - x*)||_F <= ||D^-1 (R - K x)||_F / lambda``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eigh_tridiagonal

__all__ = ["Quadrature", "ShiftInvert", "lanczos", "log_bisect", "pcg", "shift_invert"]

Array = NDArray[np.float64]


def _colnorms(X: Array) -> Array:
    return np.sqrt(np.einsum("ij,ij->j", X, X))


@dataclass
class Quadrature:
    """Gauss quadrature model of ``phi`` from ``j`` Lanczos steps per column.

    Attributes
    ----------
    nodes, weights : list of ndarray
        Per column: Ritz values ``theta`` (eigenvalues of ``T_j``) and the squared first
        components of its eigenvectors times ``||c_col||^2``.
    order : int
        Iterated Tikhonov order ``k``.
    """

    nodes: list[Array]
    weights: list[Array]
    order: int = 1
    _flat_nodes: Array = field(init=False, repr=False)
    _flat_weights: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._flat_nodes = (
            np.maximum(np.concatenate(self.nodes), 0.0) if self.nodes else np.zeros(0)
        )
        self._flat_weights = np.concatenate(self.weights) if self.weights else np.zeros(0)

    def phi(self, lam: float, order: int | None = None) -> float:
        """``phi_j(lambda)``: sum over columns of ``sum_i w_i f(theta_i)`` (order ``k``)."""
        k = self.order if order is None else order
        th, w = self._flat_nodes, self._flat_weights
        return float(np.dot(w, th ** (2 * k - 2) / (th + lam) ** (2 * k)))

    def root(self, tau: float, lo: float, hi: float, order: int | None = None) -> float:
        """``lambda`` in ``[lo, hi]`` with ``phi_j(lambda) = tau`` (to 1e-6 relative)."""
        return log_bisect(lambda lam: self.phi(lam, order), tau, lo, hi, rtol=1e-6)


def log_bisect(
    phi: Callable[[float], float], tau: float, lo: float, hi: float, rtol: float = 1e-9
) -> float:
    """Root of a decreasing ``phi(lambda) = tau`` in ``[lo, hi]`` by bisection on ``log lambda``
    (an end of the interval when the root is outside)."""
    if phi(lo) <= tau:
        return lo
    if phi(hi) >= tau:
        return hi
    a, b = math.log(lo), math.log(hi)
    while b - a > rtol:
        m = 0.5 * (a + b)
        if phi(math.exp(m)) > tau:
            a = m
        else:
            b = m
    return math.exp(0.5 * (a + b))


def lanczos(
    apply_mt: Callable[[Array], Array],
    c: Array,
    steps: int,
    stop: Callable[[Quadrature, Quadrature], bool] | None = None,
    order: int = 1,
    every: int = 1,
) -> tuple[Quadrature, Quadrature, int]:
    """Lanczos on ``M_t`` from each column of ``c``; Gauss and Gauss-Radau models of ``phi``.

    For ``f(mu) = mu^(2k-2) / (mu + lambda)^(2k)`` the Gauss rule underestimates ``phi`` and the
    Gauss-Radau rule with a node at 0 (below the spectrum of the positive semi-definite
    ``M_t``) overestimates it (for ``k = 1`` the signs of the derivatives of ``f`` decide it,
    Golub and Meurant 2010, ch. 6), so their roots bracket ``lambda*`` as the steps grow.

    Parameters
    ----------
    apply_mt : callable
        ``V -> M_t V`` for an ``(m, s)`` block.
    c : ndarray, shape (m, s)
    steps : int
        Maximum number of steps (products with ``M_t``).
    stop : callable, optional
        Called with the Gauss and Radau models after every step; ``True`` ends the recurrence.
    order : int
        Iterated Tikhonov order of the models.
    every : int
        After the fourth step, build the models (and call ``stop``) every ``every`` steps only.

    Returns
    -------
    gauss, radau : Quadrature
    int
        Steps done.
    """
    norms = _colnorms(c)
    live = norms > 0
    beta0 = norms[live]
    V = c[:, live] / beta0
    V_prev = np.zeros_like(V)
    alphas: list[Array] = []
    betas: list[Array] = []
    b_prev = np.zeros(V.shape[1])
    gauss = radau = Quadrature([], [], order)
    done = 0
    for j in range(steps):
        W = apply_mt(V) - V_prev * b_prev
        a = np.einsum("ij,ij->j", V, W)
        W -= V * a
        b = _colnorms(W)
        alphas.append(a)
        betas.append(b)
        done = j + 1
        broke = not np.all(b > 1e-14 * np.abs(a).max())
        if done <= 4 or done % every == 0 or done == steps or broke:
            gauss, radau = _models(alphas, betas, beta0, order)
            if (stop is not None and stop(gauss, radau)) or broke:
                break
        V_prev, V, b_prev = V, W / b, b
    return gauss, radau, done


def _models(
    alphas: list[Array], betas: list[Array], beta0: Array, order: int
) -> tuple[Quadrature, Quadrature]:
    A = np.array(alphas)
    B = np.array(betas)
    j = A.shape[0]
    g_nodes, g_weights, r_nodes, r_weights = [], [], [], []
    for col in range(A.shape[1]):
        a, b = A[:, col], B[:, col]
        th, Z = eigh_tridiagonal(a, b[: j - 1])
        g_nodes.append(th)
        g_weights.append(beta0[col] ** 2 * Z[0] ** 2)
        # Gauss-Radau: extend T_j by one row so that 0 is an eigenvalue (Golub's rule):
        # alpha_{j+1} = b_j^2 e_j^T T_j^-1 e_j, from the Ritz values and vectors above
        with np.errstate(divide="ignore", invalid="ignore"):
            last = float(np.sum(Z[-1] ** 2 / th)) if np.all(th > 0) else np.inf
        if np.isfinite(last):
            ar = np.append(a, b[j - 1] ** 2 * last)
            thr, Zr = eigh_tridiagonal(ar, b[:j])
            r_nodes.append(thr)
            r_weights.append(beta0[col] ** 2 * Zr[0] ** 2)
        else:
            r_nodes.append(th)
            r_weights.append(beta0[col] ** 2 * Z[0] ** 2)
    return Quadrature(g_nodes, g_weights, order), Quadrature(r_nodes, r_weights, order)


def pcg(
    apply_k: Callable[[Array], Array],
    R: Array,
    precond: Callable[[Array], Array],
    lam: float,
    d2: Array,
    x0: Array | None = None,
    rtol: float = 1e-10,
    maxiter: int = 5000,
    bound: Callable[[Array, Array], float] | None = None,
) -> tuple[Array, int, bool]:
    """Preconditioned CG for ``K X = R`` column by column, ``K = M + lambda diag(d2)``.

    Stops when ``bound(R_k, Z_k) <= rtol ||D X||_F`` for the true residual ``R_k`` and the
    preconditioned one ``Z_k``, where ``bound`` bounds the error ``||D (X - X*)||_F``; by default
    ``||D^-1 R_k||_F / lambda`` (module docstring). The test costs one fused pass per step: the
    bound is a weighted sum of squares, and ``||D X||`` is recomputed only when the bound comes
    within a factor 4 of the stale value (or every :data:`_NORM_EVERY` steps), so a stop is
    never taken on a stale norm.

    Returns
    -------
    X : ndarray, shape (m, s)
    products : int
        Products with ``K`` (true-residual checks included).
    converged : bool
    """
    d2v = np.asarray(d2, dtype=np.float64)
    X = np.zeros_like(R) if x0 is None else np.array(x0, dtype=np.float64, copy=True)
    if bound is None:
        inv_d2 = 1.0 / d2v
        bound = lambda Rk, Zk: math.sqrt(_wsq(Rk, inv_d2)) / lam  # noqa: E731
    products = 0
    size = [0.0, -1]  # ||D X||_F and the step it was computed at

    def small(Rk: Array, Zk: Array, step: int, fresh: bool = False) -> bool:
        b = bound(Rk, Zk)
        if fresh or size[1] < 0 or step - size[1] >= _NORM_EVERY or b <= 4 * rtol * size[0]:
            size[:] = [math.sqrt(_wsq(X, d2v)), step]
            return b <= rtol * max(size[0], 1e-300)
        return False

    if not np.any(R):
        return np.zeros_like(R), 0, True
    Rk = R.copy()
    if x0 is not None:
        Rk -= apply_k(X)
        products += 1
    ok = False
    for _restart in range(4):
        Z = precond(Rk)
        Pk = Z.copy()
        rz = np.einsum("ij,ij->j", Rk, Z)
        while products < maxiter and not small(Rk, Z, products):
            KP = apply_k(Pk)
            products += 1
            pKp = np.einsum("ij,ij->j", Pk, KP)
            alpha = np.divide(rz, pKp, out=np.zeros_like(rz), where=pKp > 0)
            KP *= alpha
            Rk -= KP
            X += Pk * alpha
            Z = precond(Rk)
            rz_new = np.einsum("ij,ij->j", Rk, Z)
            beta = np.divide(rz_new, rz, out=np.zeros_like(rz), where=rz > 0)
            Pk *= beta
            Pk += Z
            rz = rz_new
        Rk = R - apply_k(X)  # the recursive residual drifts: confirm with the true one
        products += 1
        ok = small(Rk, precond(Rk), products, fresh=True)
        if ok or products >= maxiter:
            break
    return X, products, ok


#: steps between refreshes of ``||D X||`` in :func:`pcg`'s stopping test
_NORM_EVERY = 8


def _wsq(X: Array, w: Array) -> float:
    """``sum_ij w_i X_ij^2`` in one pass (no temporaries)."""
    return float(np.einsum("ij,ij,i->", X, X, w, optimize=False))


@dataclass
class ShiftInvert:
    """Model of ``phi`` near ``lambda_0`` from Lanczos on ``S = (M_t + lambda_0 I)^-1``.

    With ``theta = 1 / (mu + lambda_0)`` and ``delta = lambda - lambda_0`` the terms of ``phi``
    are ``theta^2 (1 - lambda_0 theta)^(2k-2) / (1 + delta theta)^(2k)``, analytic on the
    spectrum ``(0, 1/lambda_0]`` of ``S`` for ``delta > -lambda_0``: the Gauss rule of ``j`` steps
    converges geometrically, fast for ``lambda`` within a few times ``lambda_0``.
    """

    lam0: float
    order: int
    live: NDArray[np.bool_]
    norms: Array
    thetas: list[Array]
    vectors: list[Array]
    basis: list[Array]

    def phi(self, lam: float) -> float:
        d, k = lam - self.lam0, self.order
        th = np.concatenate(self.thetas)
        w = np.concatenate(
            [nrm**2 * Z[0] ** 2 for nrm, Z in zip(self.norms, self.vectors, strict=True)]
        )
        g = th**2 * (1 - self.lam0 * th) ** (2 * k - 2) / (1 + d * th) ** (2 * k)
        return float(np.dot(w, g))

    def vector(self, lam: float, h: Callable[[Array, float], Array]) -> Array:
        """``h(S) c`` from the Krylov basis (Galerkin), shape (m, s); ``h(theta, delta)``.

        E.g. ``h = theta / (1 + delta theta)`` gives ``(M_t + lambda I)^-1 c``.
        """
        d = lam - self.lam0
        out = np.zeros((self.basis[0].shape[0], self.live.size))
        cols = np.flatnonzero(self.live)
        for col, (nrm, th, Z) in enumerate(zip(self.norms, self.thetas, self.vectors, strict=True)):
            coef = Z @ (h(th, d) * Z[0]) * nrm
            for i in range(coef.size):
                out[:, cols[col]] += coef[i] * self.basis[i][:, col]
        return out


def shift_invert(
    apply_s: Callable[[Array], Array],
    c: Array,
    lam0: float,
    order: int,
    steps: int,
    stop: Callable[[ShiftInvert], bool],
) -> tuple[ShiftInvert, int]:
    """Lanczos (fully reorthogonalized) on ``S`` from each column of ``c``; one solve per step.

    Returns the model after ``stop(model)`` holds or ``steps`` steps, and the steps done.
    Columns of ``c`` that vanish are dropped from the model (they add nothing to ``phi``).
    """
    norms = _colnorms(c)
    live = norms > 0
    c = c[:, live]
    norms = norms[live]
    basis = [c / norms]
    alphas: list[Array] = []
    betas: list[Array] = []
    model = ShiftInvert(lam0, order, live, norms, [], [], basis)
    done = 0
    for j in range(steps):
        W = apply_s(basis[j])
        a = np.einsum("ij,ij->j", basis[j], W)
        for _ in range(2):  # full reorthogonalization, twice is enough
            for Q in basis:
                W -= Q * np.einsum("ij,ij->j", Q, W)
        b = _colnorms(W)
        alphas.append(a)
        done = j + 1
        A = np.array(alphas)
        B = np.array(betas).reshape(j, A.shape[1])
        thetas, vectors = [], []
        for col in range(A.shape[1]):
            th, Z = eigh_tridiagonal(A[:, col], B[:, col])
            thetas.append(np.clip(th, 0.0, 1.0 / lam0))
            vectors.append(Z)
        model = ShiftInvert(lam0, order, live, norms, thetas, vectors, basis[: j + 1])
        if stop(model) or not np.all(b > 1e-13 * np.abs(a).max()):
            break
        betas.append(b)
        basis.append(W / b)
    return model, done
