"""The automatic lambda in lambda-space: risk curves from one Lanczos run (issue 37).

In the internal frame, with ``Y = D E``, ``M_t = D^-1 M D^-1`` and iterated Tikhonov of order
``k`` (eq. 15), the residual operator is ``G_k(lambda) = (M_t (M_t + lambda I)^-1)^k`` and the
smoother ``H_k = I - G_k``: ``phi(lambda) = ||G_k Q||_F^2`` for the data ``Q`` (here through
``c = D^-1 r``, ``y_k = M_t^(k-1) (M_t + lambda)^-k c``). Noise ``S e`` in ``Q`` (``e`` white
with variance ``sigma^2`` per unknown and column; ``S = diag(omega_i sigma_i / sigma)``, the data
weights' noise scale) gives (Mallows' C_L, Stein's unbiased risk; Vogel 2002, ch. 7)::

    E ||H Q - Q_0||^2 = E phi(lambda) - 2 c sigma^2 t(lambda) + c sigma^2 tr S^2,
    t(lambda) = tr(S G_k(lambda) S),

with ``c`` coordinate columns, so the **unbiased predictive risk** is
``U(lambda) = phi(lambda) - 2 c sigma^2 t(lambda) + c sigma^2 tr S^2`` and **GCV** is
``V(lambda) = phi(lambda) / t(lambda)^2`` (Golub, Heath and Wahba 1979); Wahba's noise estimate
at a lambda is ``sigma_W^2 = phi / (c t)``.

``t(lambda)`` for every lambda comes from the same recurrence: probe columns ``S z_j`` beside
the data's, and the Gauss rule of each probe's tridiagonal (stochastic Lanczos quadrature;
Golub and Meurant; Ubaru, Chen and Saad 2017): ``z^T S g(M_t) S z ~ ||S z||^2 sum_i Z_1i^2
g(theta_i)``. The probes are functions of the geometry, not of the order of the points
(:func:`probe_block`), so the rule is equivariant under renumbering, rigid motions and scaling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eigh_tridiagonal, eigvalsh_tridiagonal, solve_banded

__all__ = [
    "PROBE_FREQUENCIES",
    "RiskCurves",
    "gauss_rule",
    "invariant_radius",
    "probe_block",
    "radau_rule",
    "run_rules",
]

Array = NDArray[np.float64]
#: Angular frequencies ``K_j`` of the probes ``z_ij = sqrt(2) sin(K_j rho_i + theta_j)`` in
#: units of the RMS radius: neighbouring points differ in ``rho`` by about a spacing, so the
#: phases of neighbours differ by hundreds of radians on any sampling (decorrelated), while a
#: rounding-level change of ``rho`` (1e-12) moves ``z`` by ~1e-7.
PROBE_FREQUENCIES = (104729.0, 130363.0, 155921.0, 181081.0, 206197.0, 230999.0, 256199.0,
                     281381.0)  # fmt: skip
_PHASES = (0.0, 1.1, 2.3, 0.4, 1.7, 2.9, 0.8, 2.0)


def invariant_radius(points: Array) -> Array:
    """``rho_i = ||p_i - mean|| / RMS radius``: invariant under translation, rotation, uniform
    scaling and renumbering (to rounding)."""
    P = np.asarray(points, dtype=np.float64)
    centred = P - P.mean(axis=0)
    rho = np.sqrt(np.einsum("ij,ij->i", centred, centred))
    scale = float(np.sqrt(np.mean(rho**2)))
    return rho / scale if scale > 0 else rho


def probe_block(rho: Array, count: int) -> Array:
    """``count`` probe columns ``sqrt(2) sin(K_j rho_i + theta_j)`` (shape ``(len(rho),
    count)``): mean square 1 per entry, uncorrelated between neighbours (module docstring)."""
    count = min(count, len(PROBE_FREQUENCIES))
    K = np.asarray(PROBE_FREQUENCIES[:count])
    theta = np.asarray(_PHASES[:count])
    return math.sqrt(2.0) * np.sin(np.outer(rho, K) + theta)


Rule = tuple[Array, Array]


def gauss_rule(a: Array, b: Array, beta0: float) -> Rule:
    """Nodes and weights of the Gauss rule of a Lanczos tridiagonal (``alpha = a``, ``beta =
    b``, ``j = len(a)``), without its eigenvectors: the weight of node ``theta_i`` is
    ``beta0^2 Z_1i^2 = beta0^2 prod_k (theta_i - theta^_k) / prod_(l != i) (theta_i -
    theta_l)`` with ``theta^`` the eigenvalues of ``T`` without its first row and column
    (Golub and Meurant, 2010, sec. 6.2). Two eigenvalue computations, ``O(j^2)``: 3x cheaper
    than :func:`scipy.linalg.eigh_tridiagonal` with vectors at ``j = 1000`` (agreement 1e-12)."""
    j = a.size
    if j == 0 or beta0 == 0:
        return np.zeros(0), np.zeros(0)
    th = eigvalsh_tridiagonal(a, b[: j - 1], lapack_driver="sterf") if j > 1 else a.copy()
    if j == 1:
        return np.maximum(th, 0.0), np.array([beta0**2])
    hat = (eigvalsh_tridiagonal(a[1:], b[1 : j - 1], lapack_driver="sterf") if j > 2
           else a[1:].copy())  # fmt: skip
    diff = th[:, None] - th[None, :]
    np.fill_diagonal(diff, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        logw = np.sum(np.log(np.abs(th[:, None] - hat[None, :])), axis=1)
        logw -= np.sum(np.log(np.abs(diff)), axis=1)
    if not np.all(np.isfinite(logw) | (logw == -np.inf)) or np.any(diff == 0):
        th, Z = eigh_tridiagonal(a, b[: j - 1])  # repeated nodes: the eigenvectors
        return np.maximum(th, 0.0), beta0**2 * Z[0] ** 2
    w = np.exp(logw)
    w /= max(float(w.sum()), 1e-300)  # the first components of an orthogonal matrix
    return np.maximum(th, 0.0), beta0**2 * w


def radau_rule(a: Array, b: Array, beta0: float, beta_last: float) -> Rule:
    """The Gauss-Radau rule with a node at 0: ``T`` extended by one row with ``alpha =
    beta_j^2 e_j^T T^-1 e_j`` (Golub's rule), as :attr:`.lanczos_run._Column.radau`."""
    j = a.size
    if j == 0 or beta_last == 0.0:
        return gauss_rule(a, b, beta0)
    e = np.zeros(j)
    e[-1] = 1.0
    band = np.zeros((3, j))
    band[0, 1:], band[1], band[2, :-1] = b[: j - 1], a, b[: j - 1]
    try:
        inv = float(solve_banded((1, 1), band, e)[-1])
    except np.linalg.LinAlgError:
        return gauss_rule(a, b, beta0)
    if not np.isfinite(inv) or inv <= 0:
        return gauss_rule(a, b, beta0)
    return gauss_rule(np.append(a, beta_last**2 * inv), np.append(b[: j - 1], beta_last), beta0)


def run_rules(alphas: list[Array], betas: list[Array], beta0: Array, length: Array,
              radau: bool = False) -> Rule:  # fmt: skip
    """The Gauss (or Gauss-Radau) rules of every column of a run, concatenated."""
    n = len(alphas)
    if n == 0:
        return np.zeros(0), np.zeros(0)
    A, B = np.array(alphas), np.array(betas)
    nodes, weights = [], []
    for col in range(A.shape[1]):
        if beta0[col] == 0:
            continue
        j = min(int(length[col]), n) if length[col] >= 0 else n
        exact = 0 <= length[col] <= n
        a, b = A[:j, col], B[:j, col]
        last = 0.0 if exact else float(b[j - 1])
        th, w = radau_rule(a, b, float(beta0[col]), last) if radau else gauss_rule(
            a, b, float(beta0[col]))
        nodes.append(th)
        weights.append(w)
    return np.concatenate(nodes), np.concatenate(weights)


@dataclass(frozen=True)
class RiskCurves:
    """``phi``, ``t`` and their derivatives at any lambda from one run's quadrature rules.

    Attributes
    ----------
    data : tuple of ndarray
        Nodes and weights of the data columns' rule (``phi_k``).
    probes : tuple of ndarray
        Nodes and weights of the probe columns' rule, probes started at ``S z_j``.
    order : int
        Iterated Tikhonov order ``k``.
    count : int
        Number of probes ``p`` (``t`` is their mean).
    columns : int
        Coordinate columns ``c`` of the data.
    s2 : float
        ``tr S^2``.
    """

    data: Rule
    probes: Rule
    order: int
    count: int
    columns: int
    s2: float

    def phi(self, lam: Array) -> Array:
        """``phi_k(lambda)`` (Gauss rule), shape of ``lam``."""
        th, w = self.data
        k = self.order
        x = np.atleast_1d(lam)[:, None]
        return np.asarray((th ** (2 * k - 2) / (th + x) ** (2 * k)) @ w).reshape(np.shape(lam))

    def dphi(self, lam: Array) -> Array:
        """``d phi_k / d lambda``."""
        th, w = self.data
        k = self.order
        x = np.atleast_1d(lam)[:, None]
        f = -2 * k * th ** (2 * k - 2) / (th + x) ** (2 * k + 1)
        return np.asarray(f @ w).reshape(np.shape(lam))

    def trace(self, lam: Array) -> Array:
        """``t(lambda) = tr(S G_k S)`` (probe mean)."""
        th, w = self.probes
        k = self.order
        x = np.atleast_1d(lam)[:, None]
        return np.asarray(((th / (th + x)) ** k) @ w).reshape(np.shape(lam)) / self.count

    def dtrace(self, lam: Array) -> Array:
        """``d t / d lambda``."""
        th, w = self.probes
        k = self.order
        x = np.atleast_1d(lam)[:, None]
        f = -k * th**k / (th + x) ** (k + 1)
        return np.asarray(f @ w).reshape(np.shape(lam)) / self.count

    def upre(self, lam: Array, sigma2: float) -> Array:
        """``U(lambda)`` with noise variance ``sigma2`` (internal frame)."""
        c = self.columns
        return self.phi(lam) - 2 * c * sigma2 * self.trace(lam) + c * sigma2 * self.s2

    def gcv(self, lam: Array) -> Array:
        """``V(lambda) = phi / t^2`` (a constant factor left out)."""
        t = np.maximum(self.trace(lam), 1e-300)
        return self.phi(lam) / t**2

    def wahba_sigma2(self, lam: float) -> float:
        """``sigma_W^2 = phi / (c t)`` at ``lam``."""
        t = float(self.trace(np.asarray(lam)))
        return float(self.phi(np.asarray(lam))) / max(self.columns * t, 1e-300)

    def upre_min(self, sigma2: float, lo: float, hi: float) -> float:
        """The global minimiser of ``U`` on ``[lo, hi]``: the best of a log grid, then the
        root of ``U' = phi' - 2 c sigma^2 t'`` in the grid cell around it (bisection in log
        lambda; an end of the interval when the minimum is there)."""
        du = lambda x: self.dphi(x) - 2 * self.columns * sigma2 * self.dtrace(x)  # noqa: E731
        return _argmin(lambda x: self.upre(x, sigma2), du, lo, hi)

    def gcv_min(self, lo: float, hi: float) -> float:
        """The global minimiser of ``V`` on ``[lo, hi]`` (as :meth:`upre_min`, on
        ``(log V)' = phi'/phi - 2 t'/t``)."""

        def dlog(x: Array) -> Array:
            phi = np.maximum(self.phi(x), 1e-300)
            return self.dphi(x) / phi - 2 * self.dtrace(x) / np.maximum(self.trace(x), 1e-300)

        return _argmin(lambda x: np.log(np.maximum(self.gcv(x), 1e-300)), dlog, lo, hi)


GRID = 121


def _argmin(f, df, lo: float, hi: float) -> float:  # type: ignore[no-untyped-def]
    grid = np.geomspace(lo, hi, GRID)
    values = f(grid)
    i = int(np.argmin(values))
    if i == 0:
        return float(grid[0])
    if i == GRID - 1:
        return float(grid[-1])
    a, b = math.log(grid[i - 1]), math.log(grid[i + 1])
    da = float(df(np.asarray(math.exp(a))))
    db = float(df(np.asarray(math.exp(b))))
    if not (da < 0 < db):
        return float(grid[i])
    while b - a > 1e-12:
        mid = 0.5 * (a + b)
        if float(df(np.asarray(math.exp(mid)))) < 0:
            a = mid
        else:
            b = mid
    return math.exp(0.5 * (a + b))
