"""The record the finish stage returns (:func:`service.core.pipeline.finish`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.core.finish.outliers import Outliers
from service.core.finish.residual import BackOff
from service.core.finish.tangential import TangentialStep

__all__ = ["Finished"]


@dataclass(frozen=True)
class Finished:
    """The final points and what the finishing steps did.

    Attributes
    ----------
    X : ndarray, shape (n, s)
        The points in the input's frame.
    volume_scale : float or None
        The rescaling about the centroid that kept the volume or area (sections 8-9).
    tangential : TangentialStep or None
        The tangential step of normal displacement on meshes, when it applies.
    outliers : Outliers or None
        The outliers as this stage leaves them (the one record the plan and the report read);
        ``None`` without data weights.
    backoff : BackOff or None
        Where the residual test (:mod:`~service.core.finish.residual`) put shape back.
    """

    X: NDArray[np.float64]
    volume_scale: float | None = None
    tangential: TangentialStep | None = None
    outliers: Outliers | None = None
    backoff: BackOff | None = None
