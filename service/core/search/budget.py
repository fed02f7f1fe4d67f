"""The smoothing budget in its two units: ``tau`` and ``rms`` (report eq. 3, section 6).

``tau`` bounds the weighted deviation ``||D(X - P)||_F^2 = sum_i omega_i^2 ||x_i - p_i||^2``.
``rms`` states the same budget as a root-mean-square displacement per point, weighted like
``tau`` and taken over the points that can move (fixed points never move)::

    tau = rms^2 * W,    W = sum_i omega_i^2 over the free points

This module is the one place that conversion is written; the engine's target
(:func:`~service.core.search.target.resolve_tau`), the range check at submit
(:mod:`~service.core.tau_range`), :func:`~service.core.info.describe` and the CLI's
messages use it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from service.core.geometry import Geometry

__all__ = ["free_weight", "rms_range", "rms_to_tau", "tau_to_rms"]


def free_weight(geometry: Geometry, fixed: NDArray[np.bool_] | None = None) -> float:
    """``W = sum omega_i^2`` over the points not in ``fixed`` (default: the input's fixed set)."""
    omega = geometry.omega()
    mask = geometry.fixed_mask() if fixed is None else fixed
    return float(np.sum(omega[~mask] ** 2))


def rms_to_tau(rms: float, weight: float) -> float:
    """``tau = rms^2 W`` (``W`` from :func:`free_weight`)."""
    return float(rms) ** 2 * float(weight)


def tau_to_rms(tau: float, weight: float) -> float:
    """``rms = sqrt(tau / W)``; ``0`` when nothing can move (``W = 0``)."""
    return math.sqrt(float(tau) / float(weight)) if weight > 0 else 0.0


def rms_range(rms: float, tau: float, tau_max: float) -> float:
    """The upper end of the valid ``rms`` when ``rms`` gave ``tau`` and ``tau`` must stay
    below ``tau_max`` (``W = tau / rms^2``, so ``rms`` scales with ``sqrt(tau)``)."""
    return tau_to_rms(tau_max, float(tau) / float(rms) ** 2)
