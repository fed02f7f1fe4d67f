"""Closed-form kernels of one point's neighbourhood in 3-D (numba device functions, compiled
into their callers: the data weights' fits, :mod:`service.core.noise.fast_fits`, and the normal
frames, :mod:`service.core.system.fast_frames`): the centred covariance of the neighbours, the
eigenvalues of a symmetric 3 x 3 (Smith 1961) with the unit eigenvector of the smallest, and a
tangent pair orthonormal to a normal."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

# device functions only (called from compiled code; none has a Python-level caller)
__all__: list[str] = []

Array = NDArray[np.float64]


@njit(cache=True)
def centred_covariance(
    P: Array, row: NDArray[np.int64], kk: int
) -> tuple[float, float, float, float, float, float, float, float, float]:  # pragma: no cover
    """``(mx, my, mz, c00, c01, c02, c11, c12, c22)``: the mean of the points ``P[row[:kk]]``
    and the sums of the products of their centred coordinates."""
    mx = my = mz = 0.0
    for t in range(kk):
        j = row[t]
        mx += P[j, 0]
        my += P[j, 1]
        mz += P[j, 2]
    mx, my, mz = mx / kk, my / kk, mz / kk
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for t in range(kk):
        j = row[t]
        qx, qy, qz = P[j, 0] - mx, P[j, 1] - my, P[j, 2] - mz
        c00 += qx * qx
        c01 += qx * qy
        c02 += qx * qz
        c11 += qy * qy
        c12 += qy * qz
        c22 += qz * qz
    return mx, my, mz, c00, c01, c02, c11, c12, c22


@njit(cache=True)
def tangent_pair(
    nx: float, ny: float, nz: float
) -> tuple[float, float, float, float, float, float]:  # pragma: no cover
    """An orthonormal tangent pair of the unit normal ``n``: ``t1 = n x e_k`` for the axis least
    aligned with ``n`` (normalised), ``t2 = n x t1``."""
    if abs(nx) <= abs(ny) and abs(nx) <= abs(nz):
        ax, ay, az = 0.0, nz, -ny
    elif abs(ny) <= abs(nz):
        ax, ay, az = -nz, 0.0, nx
    else:
        ax, ay, az = ny, -nx, 0.0
    s = 1.0 / math.sqrt(ax * ax + ay * ay + az * az)
    t1x, t1y, t1z = ax * s, ay * s, az * s
    return t1x, t1y, t1z, ny * t1z - nz * t1y, nz * t1x - nx * t1z, nx * t1y - ny * t1x


@njit(cache=True)
def eig3(
    c00: float, c01: float, c02: float, c11: float, c12: float, c22: float
) -> tuple[float, float, float, float, float]:  # pragma: no cover
    """``mu_1 >= mu_2`` of a symmetric 3 x 3 and the unit eigenvector of its smallest
    eigenvalue (zero when it is not defined)."""
    p1 = c01 * c01 + c02 * c02 + c12 * c12
    q = (c00 + c11 + c22) / 3.0
    p2 = (c00 - q) ** 2 + (c11 - q) ** 2 + (c22 - q) ** 2 + 2.0 * p1
    if p2 <= 0.0:
        return q, q, 0.0, 0.0, 0.0
    p = math.sqrt(p2 / 6.0)
    b00, b11, b22 = (c00 - q) / p, (c11 - q) / p, (c22 - q) / p
    b01, b02, b12 = c01 / p, c02 / p, c12 / p
    det = (
        b00 * (b11 * b22 - b12 * b12)
        - b01 * (b01 * b22 - b12 * b02)
        + b02 * (b01 * b12 - b11 * b02)
    )
    h = min(max(det / 2.0, -1.0), 1.0)
    phi = math.acos(h) / 3.0
    mu1 = q + 2.0 * p * math.cos(phi)
    mu3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    mu2 = 3.0 * q - mu1 - mu3
    x, y, z = null3(c00, c01, c02, c11, c12, c22, mu3)
    if x == y == z == 0.0:
        return mu1, mu2, 0.0, 0.0, 0.0
    # the trigonometric mu3 is only sqrt(eps)-accurate when mu1 ~ mu2 (acos near +-1, an
    # isotropic tangent plane): one Rayleigh quotient makes it eps-accurate, then again
    mu3 = (x * (c00 * x + c01 * y + c02 * z) + y * (c01 * x + c11 * y + c12 * z)
           + z * (c02 * x + c12 * y + c22 * z))  # fmt: skip
    x2, y2, z2 = null3(c00, c01, c02, c11, c12, c22, mu3)
    if not x2 == y2 == z2 == 0.0:
        x, y, z = x2, y2, z2
    return mu1, mu2, x, y, z


@njit(cache=True)
def null3(
    c00: float, c01: float, c02: float, c11: float, c12: float, c22: float, mu: float
) -> tuple[float, float, float]:  # pragma: no cover
    """Unit null vector of ``C - mu I`` from the largest cross product of two of its rows
    (zero when they are all zero)."""
    a00, a11, a22 = c00 - mu, c11 - mu, c22 - mu
    x1, y1, z1 = c01 * c12 - c02 * a11, c02 * c01 - a00 * c12, a00 * a11 - c01 * c01
    x2, y2, z2 = c01 * a22 - c02 * c12, c02 * c02 - a00 * a22, a00 * c12 - c01 * c02
    x3, y3, z3 = a11 * a22 - c12 * c12, c12 * c02 - c01 * a22, c01 * c12 - a11 * c02
    n1, n2, n3 = (
        x1 * x1 + y1 * y1 + z1 * z1,
        x2 * x2 + y2 * y2 + z2 * z2,
        x3 * x3 + y3 * y3 + z3 * z3,
    )
    if n1 >= n2 and n1 >= n3:
        x, y, z, nn = x1, y1, z1, n1
    elif n2 >= n3:
        x, y, z, nn = x2, y2, z2, n2
    else:
        x, y, z, nn = x3, y3, z3, n3
    if not nn > 0.0:
        return 0.0, 0.0, 0.0
    s = 1.0 / math.sqrt(nn)
    return x * s, y * s, z * s
