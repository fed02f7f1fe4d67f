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
    "MAX_WORK",
    "RESOLUTION",
    "SincFilter",
    "chebyshev_moments",
    "combine",
    "filter_system",
    "max_degree",
    "sinc_degree",
    "sinc_deviation",
    "windowed_sinc",
]

Array = NDArray[np.float64]
#: Starting degree of the filter in ``M_t`` (``2 N`` in the Laplacian): ~2N products in all;
#: doubled (up to :data:`MAX_DEGREE`) while no pass band is narrow enough for tau.
DEGREE = 24
MAX_DEGREE = 768
#: The degree's cap in unknowns: ``degree * unknowns <= MAX_WORK`` (whatever the budget: the
#: products stay bounded; issue 39), never below ``4 DEGREE``. A 1M-vertex mesh (normal
#: displacement) stops at 96 (95 products, the output from the kept vectors) where a budget its
#: normal mode cannot absorb (rms 1.73 sigma on the 1M torus) doubled to 768 (1535 products,
#: 81 s CPU); inputs up to ~130K unknowns keep :data:`MAX_DEGREE`.
MAX_WORK = 100_000_000
#: The degree resolves the pass band: at least ``RESOLUTION * sqrt(mu_max / mu_pb)`` (Chebyshev
#: polynomials of degree N resolve about 1/N^2 of [-1, 1] next to its end, and the pass band of a
#: filter in M = L^T L sits at mu_pb = k_pb^2 for a band k_pb of L). With the fixed starting
#: degree a narrow band was a blunt filter: at the best pass band, 1.4 - 1.8x the vertex error of
#: VTK's windowed-sinc on closed curves; see service/core/README.md (issue 21).
RESOLUTION = 2.0
#: Memory for keeping the Chebyshev vectors (single precision) so the output needs no second
#: pass of products: 24 vectors of a 1M-point 3-D system take 288 MB.
KEEP_BYTES = 512 * 2**20


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


class _Recurrence:
    """The Chebyshev vectors ``v_j = T_j(x(M_t)) c`` and moments, extended on demand (a filter
    of twice the degree continues the recurrence instead of starting over)."""

    def __init__(
        self,
        apply_op: Callable[[Array], Array],
        c: Array,
        mu_max: float,
        keep: list[NDArray[np.float32]] | None,
    ) -> None:
        self.apply_op, self.scale, self.keep = apply_op, 2.0 / mu_max, keep
        v = self.x_of(c)
        self.v_prev, self.v, self.j, self.products = c, v, 1, 1
        m0, m1 = _dot(c, c), _dot(c, v)
        self.m = [m0, m1, 2.0 * _dot(v, v) - m0]
        if keep is not None:
            keep += [c.astype(np.float32), v.astype(np.float32)]

    def x_of(self, V: Array) -> Array:
        out = np.asarray(self.apply_op(V), dtype=np.float64)
        out *= self.scale  # x(M_t) = M_t / (mu_max / 2) - I
        out -= V
        return out

    def extend(self, count: int) -> Array:
        """Moments ``m_0 .. m_2count`` (one product per new step, in place)."""
        while self.j < count:
            v_next = self.x_of(self.v)
            v_next *= 2.0
            v_next -= self.v_prev
            self.products += 1
            self.m += [
                2.0 * _dot(self.v, v_next) - self.m[1],
                2.0 * _dot(v_next, v_next) - self.m[0],
            ]
            if self.keep is not None:
                self.keep.append(v_next.astype(np.float32))
            self.v_prev, self.v, self.j = self.v, v_next, self.j + 1
        return np.array(self.m[: 2 * count + 1])

    def drop_vectors(self) -> None:
        if self.keep is not None:
            self.keep.clear()
            self.keep = None


def _dot(a: Array, b: Array) -> float:
    return float(np.einsum("ij,ij->", a, b))


def chebyshev_moments(
    apply_op: Callable[[Array], Array],
    c: Array,
    mu_max: float,
    count: int,
    keep: list[NDArray[np.float32]] | None = None,
) -> tuple[Array, int]:
    """``m_j = sum over columns of c^T T_j(x(M_t)) c`` for ``j = 0 .. 2 count``.

    One product per step and a fused three-term recurrence (in place, dot products without
    temporaries). With ``keep``, the vectors ``T_j(x) c`` (``j = 0 .. count``) are appended to it
    in single precision, so that any filter of degree ``<= count`` is then applied to ``c``
    without a second pass of products (:func:`combine`).

    Returns the moments and the products done (``count``).
    """
    rec = _Recurrence(apply_op, c, mu_max, keep)
    moments = rec.extend(max(count, 1))
    return moments[: 2 * count + 1], rec.products


def combine(vectors: list[NDArray[np.float32]], coef: Array) -> Array:
    """``sum_j coef_j T_j(x) c`` from the vectors kept by :func:`chebyshev_moments`."""
    out = np.zeros(vectors[0].shape, dtype=np.float64)
    for a, v in zip(coef, vectors, strict=False):
        out += a * v
    return out


def _phi(flt: SincFilter, moments: Array) -> float:
    q = flt.q()
    q2 = cheb.chebmul(q, q)
    return float(np.dot(q2, moments[: q2.size]))


def sinc_deviation(apply_op: Callable[[Array], Array], c: Array, flt: SincFilter) -> Array:
    """``q(M_t) c`` by Clenshaw's recurrence (``N - 1`` products, fused in place)."""
    scale = 2.0 / flt.mu_max
    q = flt.q()
    b1 = np.zeros_like(c)
    b2 = np.zeros_like(c)
    for coef in q[:0:-1]:
        nxt = np.asarray(apply_op(b1), dtype=np.float64)  # 2 x(M_t) b1 - b2 + coef c
        nxt *= 2.0 * scale
        nxt -= 2.0 * b1
        nxt -= b2
        nxt += coef * c
        b1, b2 = nxt, b1
    out = np.asarray(apply_op(b1), dtype=np.float64)
    out *= scale
    out -= b1
    out -= b2
    out += q[0] * c
    return out


def max_degree(unknowns: int) -> int:
    """The largest degree (``DEGREE`` doubled) for a system of ``unknowns`` entries of ``c``:
    :data:`MAX_DEGREE`, or less where ``degree * unknowns`` would exceed :data:`MAX_WORK`
    (never below ``4 DEGREE``)."""
    cap = MAX_DEGREE
    while cap > 4 * DEGREE and cap * unknowns > MAX_WORK:
        cap //= 2
    return cap


def sinc_degree(mu_pb: float, mu_max: float, start: int = DEGREE, cap: int = MAX_DEGREE) -> int:
    """``start`` doubled (up to ``cap``) until it resolves the pass band ``mu_pb``:
    ``degree >= RESOLUTION * sqrt(mu_max / mu_pb)``."""
    need = RESOLUTION * math.sqrt(mu_max / max(mu_pb, 1e-300 * mu_max))
    degree = start
    while degree < need and 2 * degree <= cap:
        degree *= 2
    return degree


def windowed_sinc(
    apply_op: Callable[[Array], Array],
    c: Array,
    tau: float,
    mu_max: float,
    *,
    degree: int = DEGREE,
    tolerance: float = TOLERANCE,
    keep: list[NDArray[np.float32]] | None = None,
) -> tuple[SincFilter, float, list[tuple[float, float]]]:
    """The pass band with ``phi = tau`` (from the moments) and the phi it reaches.

    The degree is doubled while even the narrowest pass band deviates less than ``tau``
    (heavy smoothing needs a filter that resolves ``mu << mu_max``) or while the band found is
    narrower than the degree resolves (:func:`sinc_degree`), continuing the same
    recurrence (``2N - 1`` products in all for degree ``2N``), up to :func:`max_degree` of
    ``c``'s size (the band nearest tau at that degree is returned). With ``keep``, the
    Chebyshev vectors of the returned filter's degree are left in it (see
    :func:`chebyshev_moments`) while they fit in :data:`KEEP_BYTES`; else it is left empty.

    Returns
    -------
    SincFilter
    phi : float
        ``phi`` of that pass band (from the moments).
    history : list of (float, float)
        ``(x_pb, phi)`` for every pass band evaluated.
    """
    if keep is not None:
        keep.clear()
    cap = max(max_degree(c.size), degree)
    rec = _Recurrence(apply_op, c, mu_max, keep if 4 * degree * c.size <= KEEP_BYTES else None)
    while True:
        if 4 * degree * c.size > KEEP_BYTES:
            rec.drop_vectors()
        moments = rec.extend(max(degree - 1, 1))
        flt, phi, history = _band(moments, tau, mu_max, degree, tolerance)
        mu_pb = (flt.x_pb + 1.0) * mu_max / 2.0
        met = phi >= tau * (1 - tolerance) and sinc_degree(mu_pb, mu_max, degree, cap) == degree
        if met or 2 * degree > cap:
            return flt, phi, history
        degree *= 2


def _band(
    moments: Array, tau: float, mu_max: float, degree: int, tolerance: float
) -> tuple[SincFilter, float, list[tuple[float, float]]]:
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
    unit = bool(np.all(system.d2 == 1.0))
    inv_d = 1.0 / np.sqrt(system.d2)[:, None]

    def apply_op(V: Array) -> Array:
        if unit:  # no work on unit weights
            return dev.solver.matvec(V)
        out = np.asarray(dev.solver.matvec(V * inv_d))
        out *= inv_d
        return out

    mu_max = 1.01 * system.mu_bound()
    c = system.r if unit else system.r * inv_d
    keep: list[NDArray[np.float32]] = []
    if tau is None:
        mu_pb = min(lam if lam is not None else mu_max, mu_max)
        degree = sinc_degree(mu_pb, mu_max, cap=max_degree(c.size))
        flt = SincFilter(2 * mu_pb / mu_max - 1, mu_max, degree)
    else:
        flt, _, _ = windowed_sinc(apply_op, c, tau, mu_max, tolerance=tolerance, keep=keep)
    # one pass of products: the output from the moments' own vectors when they were kept
    dc = combine(keep, flt.q()) if len(keep) >= flt.degree else sinc_deviation(apply_op, c, flt)
    U = system.U0 + (dc if unit else dc * inv_d)
    phi = float(np.sum(system.d2[:, None] * (U - system.U0) ** 2))
    edge = (flt.x_pb + 1) * mu_max / 2
    converged = tau is None or abs(phi - tau) <= tolerance * tau
    return U, LambdaSearch(edge, phi, converged, [(edge, phi)])
