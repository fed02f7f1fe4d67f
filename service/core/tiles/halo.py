"""How wide a tile's halo must be: the decay of the solution's influence with graph distance.

The solution of eq. (4) is ``X = (L^T L + lambda D^2)^-1 lambda D^2 P``. For a Laplacian whose
spectrum lies in ``[0, l]`` (``l = ||L||``) the matrix factors as
``(L - i mu)(L + i mu)`` with ``mu = sqrt(lambda)`` (``D = I``), so ``A^-1`` is a combination
of the two resolvents ``(L -+ i mu)^-1``. ``L`` couples graph neighbours only (one hop), and the
entries of the resolvent of a banded matrix decay geometrically with the hop distance ``d``:
``|[(L - z)^-1]_ij| <= C rho^-d``, ``rho`` the parameter of the Bernstein ellipse with foci at
the ends of the spectrum ``0`` and ``l`` that passes through ``z = i mu`` (Demko, Moss and
Smith 1984; Benzi and Golub 1999). Writing ``x = mu / l``,

    rho = |z' + sqrt(z'^2 - 1)|,  z' = -1 + 2 i x,    alpha = ln rho ~ sqrt(2 x) (x -> 0),

so the influence decays like ``exp(-alpha d)`` with ``alpha ~ (lambda / l^2)^(1/4) sqrt 2``:
the quarter power of lambda, as for the biharmonic operator ``Delta^2 + lambda`` whose
Green's function decays like ``exp(-lambda^(1/4) r / sqrt 2)``. (The bound from the condition
number of ``A`` alone gives ``sqrt(lambda) / l`` per two hops: far too pessimistic for small
lambda.) Iterated Tikhonov of order ``k`` composes ``k`` such solves: ``d^(k-1) rho^-d``.
Per-point weights scale lambda locally (``lambda omega_i^2``); the smallest weight of the free
points bounds the rate from below. Fixed points only shorten the influence.

A tile whose core is surrounded by ``h`` hops of halo differs from the untiled solve by the
influence of its cut boundary: ``~ exp(-alpha h)`` relative to the displacement there.
:func:`halo_hops` returns the ``h`` that brings this below ``eps``; the measured decay on
clouds, meshes and curves is checked against ``alpha`` in ``tests/core/tiles``.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

__all__ = [
    "HALO_EPS",
    "MAX_HOPS",
    "RATE_MARGIN",
    "decay_rate",
    "halo_hops",
    "operator_norm_bound",
    "spectral_norm",
]

#: Relative influence of the cut left at the core's edge. The benchmark asks for 1 % of the
#: RMS displacement; the rate is a lower bound (measured 1.07-1.62x faster) and the cut touches
#: a band of a few hops only: at 1e-2 a 200K terrain cloud's tiles (4 x 50K, lambda given)
#: differ from the untiled solve by 1.9e-6 of the displacement at 4 box hops (issue 43).
HALO_EPS = 1e-2
#: Measured decay over the predicted rate used for the halo: the prediction is a lower bound,
#: 1.07-1.62x below the measured rate with the tight norm (table in the README), ~4x on the
#: default (normal displacement, order 2, the norm bound :func:`operator_norm_bound`) of the
#: calibration cloud (200K terrain, noise 5 cm, issue 43); 2 keeps a margin on both.
RATE_MARGIN = 2.0
#: Cap on the halo width in hops (with a warning): tiny lambda would otherwise ask for halos
#: larger than any tile.
MAX_HOPS = 400


def operator_norm_bound(L: sp.spmatrix) -> float:
    """``sqrt(||L||_1 ||L||_inf) >= ||L||_2`` (no iteration)."""
    A = abs(sp.csr_matrix(L))
    one = float(np.max(np.asarray(A.sum(axis=0)))) if A.nnz else 0.0
    inf = float(np.max(np.asarray(A.sum(axis=1)))) if A.nnz else 0.0
    return math.sqrt(one * inf)


def spectral_norm(L: sp.spmatrix) -> float:
    """``||L||_2`` from Lanczos on ``L^T L`` (2 % margin added: Lanczos approaches the top
    of the spectrum from below); :func:`operator_norm_bound` when it does not converge.

    Measured on a 20K-point cloud (L(n), Delaunay k = 20): 1.554, against the bound 2.553; the
    decay rate grows like ``norm^(-1/2)``, so the tighter norm narrows the halo by 22 %.
    """
    from scipy.sparse.linalg import ArpackNoConvergence, svds

    n = min(L.shape)
    if n < 3 or L.nnz == 0:
        return operator_norm_bound(L)
    try:
        s = svds(sp.csr_matrix(L), k=1, tol=1e-3, return_singular_vectors=False,
                 random_state=0)
    except (ArpackNoConvergence, ValueError):
        return operator_norm_bound(L)
    return float(min(1.02 * float(s[0]), operator_norm_bound(L)))


def decay_rate(lam: float, norm: float, omega_min: float = 1.0) -> float:
    """``alpha = ln rho`` per hop for ``lambda`` (internal frame), ``||L|| <= norm`` and the
    smallest (scaled) weight ``omega_min`` (module docstring).

    Parameters
    ----------
    lam : float
        ``lambda > 0`` in the frame of ``L``.
    norm : float
        An upper bound of ``||L||_2`` (:func:`operator_norm_bound`).
    omega_min : float
        Smallest weight of a free point, in the same frame.

    Returns
    -------
    float
        The decay rate per hop, ``> 0`` (``inf`` for ``norm = 0``: nothing couples).
    """
    if norm <= 0:
        return math.inf
    x = math.sqrt(lam) * omega_min / norm
    z = complex(-1.0, 2.0 * x)
    root = np.sqrt(z * z - 1)
    rho = max(abs(z + root), abs(z - root))
    return float(math.log(rho)) if rho > 1 else float(math.sqrt(2 * x))


def halo_hops(alpha: float, order: int = 1, eps: float = HALO_EPS, extra: int = 0) -> int:
    """Smallest ``h`` with ``h^(k-1) exp(-alpha h) <= eps`` (plus ``extra`` hops), capped at
    :data:`MAX_HOPS`.

    Parameters
    ----------
    alpha : float
        :func:`decay_rate`.
    order : int
        Iterated Tikhonov order ``k``.
    eps : float
        Relative influence allowed at the core's edge.
    extra : int
        Hops the operator itself reads beyond a point: the stencil of ``L^T L`` (2) and, for
        normal displacement, the averaging steps of the normal estimate.
    """
    if not math.isfinite(alpha):
        return extra
    h = 1
    while h < MAX_HOPS and alpha * h - (order - 1) * math.log(h) < math.log(1 / eps):
        h += 1
    return min(h + extra, MAX_HOPS)

