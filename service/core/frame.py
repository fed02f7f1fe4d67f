"""The internal frame: coordinates centred and scaled, weights scaled, before building and solving.

Eq. (4) is invariant under moving and scaling the input, up to how lambda and phi scale. The
engine works on ``P' = (P - c) / s`` (``c`` the centre of the bounding box, ``s`` its largest
side) with weights ``omega' = omega / w`` (``w`` the largest finite weight), so georeferenced
input (coordinates ~1e6 with millimetre noise) and extreme scales are as safe as unit-size data.
With the Laplacian built in the internal frame, ``L' = s^p L`` where ``p`` is 0 for ``L^(n)``,
1 for ``L^(f)`` and 2 for ``L^(kappa)`` (the Huber threshold is scaled with the coordinates), so

    ``phi = (s w)^2 phi'``,  ``tau' = tau / (s w)^2``,  ``lambda' = lambda w^2 s^(2p)``.

Results go back as ``c + s X'`` for the points that moved; fixed points are copied from the input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.core.errors import NonFiniteCoordinates, ParameterError

__all__ = ["LAPLACIAN_POWER", "MAX_LOG10_SCALE", "Frame"]

#: Degree of homogeneity ``-p`` of each Laplacian variant in the coordinates.
LAPLACIAN_POWER = {"normalized": 0, "feature": 1, "curvature": 2}
#: Extents and weights between ``1e-100`` and ``1e100``: squared sums stay representable.
MAX_LOG10_SCALE = 100.0


@dataclass(frozen=True)
class Frame:
    """Centre, scale and weight scale of the internal frame.

    Attributes
    ----------
    center : ndarray, shape (s,)
    scale : float
        ``s > 0``.
    weight_scale : float
        ``w > 0``.
    power : int
        ``p`` of the Laplacian variant.
    """

    center: NDArray[np.float64]
    scale: float
    weight_scale: float
    power: int

    @classmethod
    def of(cls, points: NDArray[np.float64], laplacian: str) -> Frame:
        """The frame of ``points`` (weight scale 1; see :meth:`weighted`).

        Raises
        ------
        NonFiniteCoordinates
            Extents whose squares would overflow or underflow.
        """
        lo, hi = points.min(axis=0), points.max(axis=0)
        center = lo / 2 + hi / 2
        extent = float(np.max(hi / 2 - lo / 2)) * 2
        if extent > 0 and abs(math.log10(extent)) > MAX_LOG10_SCALE:
            raise NonFiniteCoordinates(
                f"the points span {extent:.3g}: squared deviations would not be representable "
                f"(supported extents 1e-{MAX_LOG10_SCALE:.0f} .. 1e{MAX_LOG10_SCALE:.0f}); "
                "rescale the input",
                field="geometry.points",
            )
        return cls(center, extent if extent > 0 else 1.0, 1.0, LAPLACIAN_POWER[laplacian])

    def weighted(self, omega: NDArray[np.float64]) -> Frame:
        """This frame with the weight scale ``w = max(omega)`` of the finite weights ``omega``.

        Raises
        ------
        NonFiniteCoordinates
            Weights whose squares would overflow or underflow.
        """
        w = float(omega.max()) if omega.size else 1.0
        wmin = float(omega.min()) if omega.size else 1.0
        if abs(math.log10(w)) > MAX_LOG10_SCALE or math.log10(w / wmin) > MAX_LOG10_SCALE:
            raise NonFiniteCoordinates(
                f"weights range over [{wmin:.3g}, {w:.3g}]: squared weights would overflow "
                f"(supported 1e-{MAX_LOG10_SCALE:.0f} .. 1e{MAX_LOG10_SCALE:.0f}, ratio at most "
                f"1e{MAX_LOG10_SCALE:.0f}); use +inf to fix a point",
                field="geometry.weights",
            )
        return Frame(self.center, self.scale, w, self.power)

    def points(self, P: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(P - c) / s``."""
        return (P - self.center) / self.scale

    def back(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """``c + s X``."""
        return self.center + self.scale * X

    @property
    def phi_factor(self) -> float:
        """``(s w)^2``: ``phi = phi_factor * phi'``."""
        return (self.scale * self.weight_scale) ** 2

    def tau_in(self, tau: float) -> float:
        """``tau' = tau / (s w)^2``: a budget (or deviation) of the input in the frame."""
        return tau / self.phi_factor

    def phi_out(self, phi: float) -> float:
        """``phi = (s w)^2 phi'``: a deviation (or budget) of the frame in the input's numbers."""
        return phi * self.phi_factor

    def _lam_factor(self) -> tuple[float, float]:
        """``w^2 s^(2p)`` as a float (``inf``/0 when not representable) and its logarithm."""
        log = 2 * math.log(self.weight_scale) + 2 * self.power * math.log(self.scale)
        try:
            value = self.weight_scale**2 * self.scale ** (2 * self.power)
        except OverflowError:
            value = math.inf
        return value, log

    def lam_in(self, lam: float) -> float:
        """``lambda' = lambda w^2 s^(2p)`` (exact when the factor is 1)."""
        factor, log = self._lam_factor()
        out = lam * factor if 0 < factor < math.inf else math.exp(math.log(lam) + log)
        if not (0 < out < math.inf):
            raise ParameterError(
                f"lam={lam:.3g} is outside the representable range for this input's scale",
                field="params.lam",
            )
        return out

    def lam_out(self, lam: float) -> float:
        """The input frame's lambda for an internal ``lambda'`` (finite, clamped)."""
        if not lam > 0:
            return 0.0
        factor, log = self._lam_factor()
        out = lam / factor if 0 < factor < math.inf else math.nan
        if 0 < out < math.inf:
            return out
        return math.exp(min(max(math.log(lam) - log, -700.0), 700.0))
