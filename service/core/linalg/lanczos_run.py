"""One Lanczos recurrence on ``M_t = D^-1 M D^-1`` from ``c = D^-1 r`` that serves the whole
Tikhonov problem: ``phi_k(lambda)`` for every lambda, bounds of it, and the solution.

With ``K(lambda) = M + lambda D^2`` (report eq. 17), ``y = D E`` and the iterated Tikhonov
deviation of order ``k`` (eq. 15; :mod:`service.core.system.deviation`)::

    y_k(lambda) = M_t^(k-1) (M_t + lambda I)^(-k) c,   phi_k(lambda) = ||y_k||^2.

``j`` Lanczos steps from each column of ``c`` give ``M_t V_j = V_j T_j + beta_j v_(j+1) e_j^T``
and, with ``T_j = Z diag(theta) Z^T``, for every lambda and no further product:

* the Gauss rule ``phi_G = sum_i w_i f(theta_i)``, ``f(mu) = mu^(2k-2) / (mu + lambda)^(2k)``,
  ``w_i = ||c||^2 Z_(1i)^2`` (Golub and Meurant), a lower bound of ``phi`` for ``k = 1``, and
  the Gauss-Radau rule with a node at 0 (an upper bound for ``k = 1``), as in
  :func:`service.core.linalg.krylov.lanczos`;
* the Galerkin vectors ``a_i = ||c|| h_i(T_j) e_1`` with ``h_i(mu) = mu^(i-1)/(mu+lambda)^i``, whose
  images ``V_j a_i`` approximate ``y_i`` (``a_1``: the conjugate-gradient iterate);
* the residuals of that chain without forming it: ``R_1 = c - (M_t + lambda) V a_1`` and
  ``R_i = M_t V a_(i-1) - (M_t + lambda) V a_i`` are ``beta_j v_(j+1)`` times
  ``(a_(i-1) - a_i)_j`` (exact arithmetic), and since the smallest eigenvalue of
  ``M_t + lambda`` is at least lambda and ``||(M_t + lambda)^-1 M_t|| <= 1``,
  ``||V a_k - y_k|| <= sum_i ||R_i|| / lambda`` (:meth:`TikhonovModel.error_bound`); with
  ``y = D E`` this is ``||D (E~ - E)||``, the bound :func:`~service.core.linalg.krylov.pcg`
  stops on.

No reorthogonalization (at 1M unknowns the basis is not affordable, and the products are the
cost): the Gauss rule stays accurate for ``phi`` when orthogonality is lost (the computed
``T_j`` is the exact Lanczos matrix of a nearby problem, Greenbaum 1989; Golub and Strakos 1994),
and the Galerkin vectors behave like conjugate gradients in finite precision (delayed, not
wrong). Nothing rests on that alone: the caller verifies the vectors with their true residuals
(:func:`true_residual_bound`). The basis is kept (``float32`` by default: a relative error of
``~1e-7`` per vector) while it fits ``keep_bytes``; beyond, :meth:`LanczosRun.combine` runs the
recurrence a second time with the stored ``alpha, beta``, resumed from its ``float64`` state at
the last kept vector (bit-identical vectors, one product per step beyond the kept ones, no inner
products; 1M torus: 312 products instead of 580).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eigh_tridiagonal

__all__ = ["BASIS_BYTES", "LanczosRun", "TikhonovModel", "true_residual_bound"]

Array = NDArray[np.float64]
#: Bytes of Lanczos vectors kept for the solution (beyond them: a second pass).
BASIS_BYTES = 2**30
#: A column whose new ``beta`` falls below this times its largest ``|alpha|`` has found an
#: invariant subspace: its model is exact and it takes no further part.
BREAKDOWN = 1e-14


class LanczosRun:
    """The recurrence on ``M_t`` from the columns of ``c`` (one product per step for all).

    Parameters
    ----------
    apply_mt : callable
        ``V -> M_t V`` for an ``(m, s)`` block.
    c : ndarray, shape (m, s)
    keep_bytes : int
        Budget for the kept basis (0: keep none).
    dtype : numpy dtype
        Storage of the kept basis.
    """

    def __init__(
        self,
        apply_mt: Callable[[Array], Array],
        c: Array,
        keep_bytes: int = BASIS_BYTES,
        dtype: type = np.float32,
    ) -> None:
        self.apply_mt = apply_mt
        self.c = np.asarray(c, dtype=np.float64)
        self.m, self.s = self.c.shape
        self.beta0 = np.linalg.norm(self.c, axis=0)
        self.length = np.where(self.beta0 > 0, -1, 0)  # steps per column; -1 while running
        safe = np.where(self.beta0 > 0, self.beta0, 1.0)
        self.V = self.c / safe
        self.V_prev = np.zeros_like(self.V)
        self.b_prev = np.zeros(self.s)
        self.alphas: list[Array] = []
        self.betas: list[Array] = []
        self._scale = np.zeros(self.s)
        self.products = 0
        self.dtype = dtype
        per_vector = self.m * self.s * np.dtype(dtype).itemsize
        self.keep_steps = int(keep_bytes // max(per_vector, 1))
        self.basis: list[NDArray[np.floating]] = []
        #: The recurrence's state (float64) when the last kept vector was stored: a second
        #: pass resumes from it instead of from ``c``.
        self._resume: tuple[int, Array, Array, Array, NDArray[np.int64]] | None = None
        self._keep(self.V)

    @property
    def steps(self) -> int:
        return len(self.alphas)

    @property
    def done(self) -> bool:
        """Every column has found an invariant subspace (its model is exact)."""
        return bool(np.all(self.length >= 0))

    def _keep(self, V: Array) -> None:
        if len(self.basis) < self.keep_steps:  # beyond: a solution from more steps than
            self.basis.append(V.astype(self.dtype))  # are kept takes a second pass
            if len(self.basis) == self.keep_steps:
                self._resume = (len(self.basis), self.V_prev.copy(), V.copy(),
                                self.b_prev.copy(), self.length.copy())  # fmt: skip

    def step(self) -> None:
        """One Lanczos step (one product with ``M_t``)."""
        W = self.apply_mt(self.V)
        self.products += 1
        W -= self.V_prev * self.b_prev
        a = np.einsum("ij,ij->j", self.V, W)
        W -= self.V * a
        b = np.sqrt(np.einsum("ij,ij->j", W, W))  # column norms (a strided norm is 3x slower)
        running = self.length < 0
        a = np.where(running, a, 0.0)
        b = np.where(running, b, 0.0)
        self.alphas.append(a)
        self.betas.append(b)
        self._scale = np.maximum(self._scale, np.abs(a))
        broke = running & ~(b > BREAKDOWN * np.maximum(self._scale, 1e-300))
        self.length[broke] = self.steps
        W /= np.where(b > 0, b, 1.0)  # in place: the values of W / b
        dead = self.length >= 0
        if dead.any():
            W[:, dead] = 0.0
        self.V_prev, self.V, self.b_prev = self.V, W, np.where(dead, 0.0, b)
        self._keep(self.V)

    def live_coefficients(self) -> tuple[list[Array], list[Array], Array]:
        """``alpha``, ``beta`` per step and ``||c||`` of the columns that are not zero (the
        arguments of :func:`service.core.linalg.krylov._models`)."""
        live = self.beta0 > 0
        return ([a[live] for a in self.alphas], [b[live] for b in self.betas],
                self.beta0[live])  # fmt: skip

    def model(self, order: int = 1, steps: int | None = None) -> TikhonovModel:
        """Gauss and Gauss-Radau models of ``phi`` (order ``k``) after the steps done (or the
        first ``steps`` of them)."""
        n = self.steps if steps is None else min(steps, self.steps)
        A = np.array(self.alphas[:n]).reshape(n, self.s)
        B = np.array(self.betas[:n]).reshape(n, self.s)
        cols = []
        for col in range(self.s):
            j = min(int(self.length[col]), n) if self.length[col] >= 0 else n
            exact = 0 <= self.length[col] <= n
            cols.append(_column(A[:j, col], B[:j, col], float(self.beta0[col]), exact))
        return TikhonovModel(cols, order)

    def combine(self, coefs: list[Array]) -> list[Array]:
        """``V_j a`` for each ``a`` of shape ``(j, s)`` (column ``col`` of ``a`` on the basis of
        column ``col``; ``j`` at most the steps done): from the kept basis when it holds the
        first ``j`` vectors, else by running the recurrence again."""
        j = max((a.shape[0] for a in coefs), default=0)
        out = [np.zeros((self.m, self.s)) for _ in coefs]
        kept = len(self.basis) >= j
        vectors = iter(self.basis[:j]) if kept else self._regenerate(j)
        for i, v in enumerate(vectors):
            for o, a in zip(out, coefs, strict=True):
                row = a[i] if i < a.shape[0] else np.zeros(self.s)
                if np.any(row):
                    o += v * row
        return out

    def _regenerate(self, j: int) -> Iterator[NDArray[np.floating]]:
        """The vectors ``v_1 .. v_j`` again: the kept ones, then the recurrence resumed from its
        state at the last kept vector (from ``c`` when none is kept) with the stored ``alpha,
        beta`` (the same operations as :meth:`step`, so bit-identical vectors; ``j - kept``
        products)."""
        if self._resume is not None:
            start, V_prev, V, b_prev, length = self._resume
            length = length.copy()
            yield from self.basis[: start - 1]
            start -= 1  # v_start is V (float64)
        else:
            safe = np.where(self.beta0 > 0, self.beta0, 1.0)
            V, V_prev, b_prev = self.c / safe, np.zeros_like(self.c), np.zeros(self.s)
            length, start = np.where(self.beta0 > 0, -1, 0), 0
        for i in range(start, j):
            yield V
            if i == j - 1:
                return
            W = self.apply_mt(V)
            self.products += 1
            W -= V_prev * b_prev
            W -= V * self.alphas[i]
            b = self.betas[i]
            stop = (length < 0) & (self.length == i + 1)
            length[stop] = i + 1
            b_safe = np.where(b > 0, b, 1.0)
            V_prev, V, b_prev = (
                V,
                np.where(length < 0, W / b_safe, 0.0),
                np.where(length < 0, b, 0.0),
            )


@dataclass(frozen=True)
class _Column:
    theta: Array  # Ritz values
    Z: Array  # eigenvectors of T_j
    beta0: float
    beta_last: float  # beta_j (0 when the column broke down: exact)
    a: Array  # the coefficients, for the Gauss-Radau rule made on demand
    b: Array

    @property
    def w(self) -> Array:
        return self.beta0**2 * self.Z[0] ** 2

    @cached_property
    def radau(self) -> tuple[Array, Array]:
        """Nodes and weights of the Gauss-Radau rule with a node at 0: ``T_j`` extended by one
        row with ``alpha = b_j^2 e_j^T T_j^-1 e_j`` (Golub's rule)."""
        th, j = self.theta, self.theta.size
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = float(np.sum(self.Z[-1] ** 2 / th)) if j and np.all(th > 0) else np.inf
        if self.beta_last == 0.0 or not np.isfinite(inv):
            return th, self.w
        rth, rZ = eigh_tridiagonal(np.append(self.a, self.beta_last**2 * inv), self.b[:j])
        return np.maximum(rth, 0.0), self.beta0**2 * rZ[0] ** 2


def _column(a: Array, b: Array, beta0: float, exact: bool) -> _Column:
    j = a.size
    if j == 0 or beta0 == 0:
        e = np.zeros(0)
        return _Column(e, np.zeros((0, 0)), beta0, 0.0, e, e)
    th, Z = eigh_tridiagonal(a, b[: j - 1])
    return _Column(np.maximum(th, 0.0), Z, beta0, 0.0 if exact else float(b[j - 1]), a, b)


@dataclass(frozen=True)
class TikhonovModel:
    """``phi_k`` and the Galerkin solution at any lambda from one run (module docstring)."""

    columns: list[_Column]
    order: int = 1

    def _rule(self, radau: bool) -> tuple[Array, Array]:
        if radau:
            return (np.concatenate([c.radau[0] for c in self.columns]),
                    np.concatenate([c.radau[1] for c in self.columns]))  # fmt: skip
        return (np.concatenate([c.theta for c in self.columns]),
                np.concatenate([c.w for c in self.columns]))  # fmt: skip

    def phi(self, lam: float | Array, radau: bool = False, order: int | None = None) -> Array:
        """``phi_k(lambda)`` (Gauss rule, or Gauss-Radau), for a scalar or an array of lambda."""
        k = self.order if order is None else order
        th, w = self._rule(radau)
        lam_arr = np.atleast_1d(np.asarray(lam, dtype=np.float64))[:, None]
        f = th ** (2 * k - 2) / (th + lam_arr) ** (2 * k)
        out = f @ w
        return out if np.ndim(lam) else out[0]

    def root(self, tau: float, lo: float, hi: float, radau: bool = False,
             rtol: float = 1e-12) -> float:  # fmt: skip
        """The lambda in ``[lo, hi]`` with ``phi_k(lambda) = tau`` (log bisection; an end of the
        interval when the root is outside)."""
        f = lambda lam: float(self.phi(lam, radau))  # noqa: E731
        if f(lo) <= tau:
            return lo
        if f(hi) >= tau:
            return hi
        a, b = math.log(lo), math.log(hi)
        while b - a > rtol:
            mid = 0.5 * (a + b)
            a, b = (mid, b) if f(math.exp(mid)) > tau else (a, mid)
        return math.exp(0.5 * (a + b))

    def galerkin(self, lam: float, power: int, inverse: int) -> Array:
        """Coefficients ``||c|| T^power (T + lambda)^-inverse e_1`` per column, shape (j, s)
        (zero-padded to the longest column)."""
        j = max((c.theta.size for c in self.columns), default=0)
        out = np.zeros((j, len(self.columns)))
        for col, c in enumerate(self.columns):
            if c.theta.size:
                h = c.theta**power / (c.theta + lam) ** inverse
                out[: c.theta.size, col] = c.Z @ (h * c.Z[0]) * c.beta0
        return out

    def chain(self, lam: float) -> list[Array]:
        """``a_1 .. a_k``: the Galerkin vectors of ``y_1 .. y_k`` (module docstring)."""
        return [self.galerkin(lam, i - 1, i) for i in range(1, self.order + 1)]

    def error_bound(self, lam: float) -> float:
        """Upper bound of ``||V a_k - y_k||_F`` from the residuals of the chain (exact
        arithmetic; the caller confirms with :func:`true_residual_bound`)."""
        total = 0.0
        for col, c in enumerate(self.columns):
            if not c.theta.size or c.beta_last == 0.0:
                continue
            prev = 0.0
            err = 0.0
            for i in range(1, self.order + 1):
                last = float(np.dot(c.Z[-1], c.Z[0] * c.theta ** (i - 1) / (c.theta + lam) ** i))
                last *= c.beta0
                err += c.beta_last * abs(prev - last) / lam
                prev = last
            total += err**2
            del col
        return math.sqrt(total)


def true_residual_bound(
    apply_mt: Callable[[Array], Array], c: Array, Y: list[Array], lam: float
) -> float:
    """``sum_i ||R_i||_F / lambda`` for the vectors ``Y = [y_1 .. y_k]`` (one product with the
    block of all of them): a rigorous bound of ``||Y[-1] - y_k||_F`` whatever the arithmetic of
    the run that produced them (module docstring)."""
    block = np.concatenate(Y, axis=1)
    MY = apply_mt(block)
    s = c.shape[1]
    bound, prev = 0.0, c
    for i, y in enumerate(Y):
        R = prev - MY[:, i * s : (i + 1) * s] - lam * y
        bound += float(np.sqrt(np.einsum("ij,ij->", R, R))) / lam
        prev = MY[:, i * s : (i + 1) * s]
    return bound
