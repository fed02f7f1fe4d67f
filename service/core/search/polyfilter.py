"""``method="windowed-sinc"``: a polynomial low-pass filter with the same tau contract.

Taubin's windowed-sinc smoothing (as VTK's ``vtkWindowedSincPolyDataFilter``) applies a
Chebyshev expansion of an ideal low-pass filter, damped by a window, to the Laplacian. Here the
filter acts on the same symmetric operator as Tikhonov smoothing, ``M_t = D^-1 M D^-1``
(:mod:`service.core.system.deviation`): in its eigenbasis (``mu_i``) the kept fraction of each mode
is
``g(mu)``, the Hamming-windowed Chebyshev series of the step that keeps ``mu < mu_pb``,
normalized so that ``g(0) = 1`` (shapes in the null space, e.g. a translation, are kept). As for
eq. (4) with ``g = lambda / (mu + lambda)``, the deviation is

    ``D E = q(M_t) c``,  ``q(mu) = (1 - g(mu)) / mu``,  ``c = D^-1 (b - M U0)``,

a polynomial of degree ``N - 1`` (it handles fixed points exactly like the Tikhonov system), and

    ``phi(mu_pb) = c^T q(M_t)^2 c = sum_j [q^2]_j m_j``

with the Chebyshev moments ``m_j = c^T T_j(x(M_t)) c`` for ``j <= 2N - 2``, which ``N - 1``
products give (``T_2j = 2 T_j^2 - 1``, ``T_2j+1 = 2 T_j T_j+1 - T_1``). So the pass band meeting
``phi = tau`` is found exactly from the moments (no factorization), and the points follow from
``N - 1`` more products (Clenshaw). ``phi`` is monotone in the pass band up to the window's
ripple; the root is bracketed on a grid and refined by bisection.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.polynomial import chebyshev as cheb
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.params import TOLERANCE
from service.core.search.roots import LambdaSearch
from service.core.system.deviation import Deviation

__all__ = [
    "DEGREE",
    "SincFilter",
    "chebyshev_moments",
    "filter_system",
    "sinc_deviation",
    "windowed_sinc",
]

Array = NDArray[np.float64]
#: Starting degree of the filter in ``M_t`` (``2 N`` in the Laplacian): ~2N products in all;
#: doubled (up to :data:`MAX_DEGREE`) while no pass band is narrow enough for tau.
DEGREE = 24
MAX_DEGREE = 768


def _hamming(n: int) -> Array:
    j = np.arange(n + 1)
    return 0.54 + 0.46 * np.cos(np.pi * j / (n + 1))


@dataclass(frozen=True)
class SincFilter:
    """The filter ``g`` with pass band ``x_pb`` (in ``x = 2 mu / mu_max - 1``) and its ``q``."""

    x_pb: float
    mu_max: float
    degree: int

    def kept(self) -> Array:
        """Chebyshev coefficients (in ``x``) of ``g``, normalized to ``g(-1) = 1``."""
        theta = math.acos(min(max(self.x_pb, -1.0), 1.0))
        j = np.arange(1, self.degree + 1)
        coef = np.concatenate(
            [[(math.pi - theta) / math.pi], -2 * np.sin(j * theta) / (j * math.pi)]
        )
        coef *= _hamming(self.degree)
        return coef / cheb.chebval(-1.0, coef)

    def q(self) -> Array:
        """Chebyshev coefficients (in ``x``) of ``q(mu) = (1 - g(mu)) / mu``, degree ``N - 1``."""
        g = self.kept()
        half = self.mu_max / 2.0

        def q(x: Any) -> Any:
            return (1.0 - cheb.chebval(x, g)) / ((x + 1.0) * half)

        return np.asarray(cheb.chebinterpolate(q, max(self.degree - 1, 0)))


def chebyshev_moments(
    apply_op: Callable[[Array], Array], c: Array, mu_max: float, count: int
) -> tuple[Array, int]:
    """``m_j = sum over columns of c^T T_j(x(M_t)) c`` for ``j = 0 .. 2 count``.

    Returns the moments and the products done (``count``).
    """
    half = mu_max / 2.0

    def x_of(V: Array) -> Array:
        return apply_op(V) / half - V

    m = np.zeros(2 * count + 1)
    v_prev, v = c, x_of(c)
    m[0], m[1] = float(np.sum(c * c)), float(np.sum(c * v))
    if count >= 1:
        m[2] = 2.0 * float(np.sum(v * v)) - m[0]
    for j in range(2, count + 1):
        v_next = 2.0 * x_of(v) - v_prev
        m[2 * j - 1] = 2.0 * float(np.sum(v * v_next)) - m[1]
        m[2 * j] = 2.0 * float(np.sum(v_next * v_next)) - m[0]
        v_prev, v = v, v_next
    return m, max(count, 1)


def _phi(flt: SincFilter, moments: Array) -> float:
    q = flt.q()
    q2 = cheb.chebmul(q, q)
    return float(np.dot(q2, moments[: q2.size]))


def sinc_deviation(apply_op: Callable[[Array], Array], c: Array, flt: SincFilter) -> Array:
    """``q(M_t) c`` by Clenshaw's recurrence (``N - 1`` products)."""
    half = flt.mu_max / 2.0
    q = flt.q()
    b1 = np.zeros_like(c)
    b2 = np.zeros_like(c)
    for coef in q[:0:-1]:
        xb1 = apply_op(b1) / half - b1
        b1, b2 = 2.0 * xb1 - b2 + coef * c, b1
    return apply_op(b1) / half - b1 - b2 + q[0] * c


def windowed_sinc(
    apply_op: Callable[[Array], Array],
    c: Array,
    tau: float,
    mu_max: float,
    *,
    degree: int = DEGREE,
    tolerance: float = TOLERANCE,
) -> tuple[SincFilter, float, list[tuple[float, float]]]:
    """The pass band with ``phi = tau`` (from the moments) and the phi it reaches.

    The degree is doubled while even the narrowest pass band deviates less than ``tau``
    (heavy smoothing needs a filter that resolves ``mu << mu_max``).

    Returns
    -------
    SincFilter
    phi : float
        ``phi`` of that pass band (from the moments).
    history : list of (float, float)
        ``(x_pb, phi)`` for every pass band evaluated.
    """
    while True:
        flt, phi, history = _band(apply_op, c, tau, mu_max, degree, tolerance)
        if phi >= tau * (1 - tolerance) or 2 * degree > MAX_DEGREE:
            return flt, phi, history
        degree *= 2


def _band(
    apply_op: Callable[[Array], Array],
    c: Array,
    tau: float,
    mu_max: float,
    degree: int,
    tolerance: float,
) -> tuple[SincFilter, float, list[tuple[float, float]]]:
    moments, _ = chebyshev_moments(apply_op, c, mu_max, max(degree - 1, 1))
    history: list[tuple[float, float]] = []

    def phi_at(theta: float) -> float:
        value = _phi(SincFilter(math.cos(theta), mu_max, degree), moments)
        history.append((math.cos(theta), value))
        return value

    # phi falls as the pass band widens (theta from pi to 0): bracket on a grid, then bisect
    thetas = np.linspace(math.pi, 0.0, 4 * degree + 1)[1:-1]
    values = np.array([phi_at(float(t)) for t in thetas])
    above = np.flatnonzero(values >= tau)
    if above.size == 0 or above.max() == thetas.size - 1:
        i = 0 if above.size == 0 else thetas.size - 1
        return SincFilter(math.cos(thetas[i]), mu_max, degree), float(values[i]), history
    i = int(above.max())
    a, b = float(thetas[i]), float(thetas[i + 1])  # phi(a) >= tau > phi(b)
    phi = float(values[i + 1])
    for _ in range(60):
        mid = 0.5 * (a + b)
        phi = phi_at(mid)
        if abs(phi - tau) <= 0.1 * tolerance * tau:
            a = b = mid
            break
        a, b = (mid, b) if phi >= tau else (a, mid)
    return SincFilter(math.cos(0.5 * (a + b)), mu_max, degree), phi, history


def filter_system(
    dev: Deviation, laplacian: str, tau: float | None, lam: float | None, tolerance: float
) -> tuple[Array, LambdaSearch]:
    """The windowed-sinc solution ``U`` of ``dev.system`` (internal frame) and its search record.

    Parameters
    ----------
    dev : Deviation
        The system; its solver's products with ``M`` are counted (no solve is made).
    laplacian : str
        Must be ``"normalized"``.
    tau : float, optional
        Target deviation; or ``lam``, the pass band's edge on lambda's scale.
    tolerance : float

    Raises
    ------
    ParameterError
        For ``L(kappa)`` and ``L(f)``: their row scales spread the spectrum beyond what a
        polynomial filter resolves.
    """
    if laplacian != "normalized":
        raise ParameterError(
            "method 'windowed-sinc' needs laplacian 'normalized': the row scales of L(kappa) "
            "and L(f) spread the spectrum beyond what a polynomial filter resolves",
            field="params.method",
        )
    system = dev.system
    d = np.sqrt(system.d2)[:, None]

    def apply_op(V: Array) -> Array:
        return dev.solver.matvec(V / d) / d

    mu_max = 1.01 * system.mu_bound()
    c = system.r / d
    if tau is None:
        mu_pb = min(lam if lam is not None else mu_max, mu_max)
        flt = SincFilter(2 * mu_pb / mu_max - 1, mu_max, DEGREE)
    else:
        flt, _, _ = windowed_sinc(apply_op, c, tau, mu_max, tolerance=tolerance)
    U = system.U0 + sinc_deviation(apply_op, c, flt) / d
    phi = float(np.sum(system.d2[:, None] * (U - system.U0) ** 2))
    edge = (flt.x_pb + 1) * mu_max / 2
    converged = tau is None or abs(phi - tau) <= tolerance * tau
    return U, LambdaSearch(edge, phi, converged, [(edge, phi)])
