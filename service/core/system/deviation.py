"""The smoothing system and its deviation function ``phi(lambda)`` (report eqs. 4, 15, 17).

A :class:`SmoothingSystem` holds the normal equations of

    ``min_U ||A U - g||_F^2 + lambda ||D (U - U0)||_F^2``

as ``M = A^T A``, ``d2 = diag(D^2)``, ``b = A^T g`` and ``U0``. For the report's smoothing
(eq. 4 with the fixed points eliminated, section 8) ``A = L_F``, ``g = -L_C P_C``, ``U0 = P_F``;
other modes (e.g. a normal-only displacement with one unknown per point) build their own.

With ``K(lambda) = M + lambda D^2`` and ``r = b - M U0``, the deviation ``E = U - U0`` of
eq. (4) is ``E_1 = K^-1 r``. :class:`Deviation` also implements iterated Tikhonov of order
``k`` (twicing): ``X_{j+1} = X_j + S(U0 - X_j)`` with the smoother ``S`` of eq. (4) acting on
the residual (whose fixed points are zero), i.e. ``E_{j+1} = K^-1 M E_j``. In the basis of the
generalized eigenvectors of ``(M, D^2)`` (eigenvalues ``mu_i``) the kept filter is
``1 - (mu_i / (mu_i + lambda))^k`` and

    ``phi(lambda) = ||D E_k||_F^2 = sum_i c_i^2 mu_i^(2k-2) / (mu_i + lambda)^(2k)``,
    ``phi'(lambda) = -2k <D^2 E_k, K^-1 D^2 E_k>``  (one more solve),

with ``c = D^-1 r``: ``phi`` is convex and strictly decreasing for every ``k``, and
``phi^(-1/(2k))`` is concave (a power mean of exponent ``-2k`` of affine functions of lambda),
which the Newton search of :mod:`service.core.search.roots` relies on. ``phi(0)`` does not depend
on ``k``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.linalg.krylov import ShiftInvert, log_bisect, shift_invert
from service.core.linalg.solver import (
    Direct,
    Gram,
    Lanczos,
    LinearSolver,
    MatrixFree,
    SolverStats,
    explicit,
)

__all__ = ["LAMBDA_FLOOR", "Deviation", "SmoothingSystem", "make_solver"]

Array = NDArray[np.float64]
#: ``lambda`` is bounded below by ``LAMBDA_FLOOR * ||M_t||`` (``M_t = D^-1 M D^-1``): the
#: condition number of eq. (17) is ``1 + ||M_t|| / lambda`` and below this bound rounding errors
#: of the size ``eps ||M_t|| / lambda`` swamp the deviation (issue 15: ``lam <= 1e-16`` gave
#: ``phi > phi(0)`` with the points collapsed).
LAMBDA_FLOOR = 1e-13
SolverChoice = Literal["cholmod", "superlu", "cg"]


@dataclass(frozen=True, eq=False)
class SmoothingSystem:
    """Normal equations of ``min ||A U - g||^2 + lambda ||D (U - U0)||^2``.

    Parameters
    ----------
    M : sparse matrix or Gram, shape (m, m)
        ``A^T A`` (symmetric positive semi-definite), formed or kept as ``A``
        (:class:`~service.core.linalg.solver.Gram`).
    d2 : ndarray, shape (m,)
        Positive diagonal of ``D^2``.
    b : ndarray, shape (m, c)
        ``A^T g``.
    U0 : ndarray, shape (m, c)
        The data the deviation is measured from.
    phi0 : float, optional
        ``phi(0)`` when known in closed form (eq. 14); see :meth:`Deviation.phi0`.
    phi0_bound : float, optional
        An upper bound of ``phi(0)`` when known (a ``tau`` above it is out of range).
    """

    M: sp.spmatrix | Gram
    d2: Array
    b: Array
    U0: Array
    phi0: float | None = None
    phi0_bound: float | None = None
    r: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        M = self.M if isinstance(self.M, Gram) else sp.csr_matrix(self.M)
        object.__setattr__(self, "M", M)
        object.__setattr__(self, "d2", np.asarray(self.d2, dtype=np.float64))
        object.__setattr__(self, "r", np.asarray(self.b - M @ self.U0))

    @property
    def size(self) -> int:
        return int(self.M.shape[0])

    def mu_bound(self) -> float:
        """Gershgorin bound of the largest eigenvalue of ``M_t = D^-1 M D^-1``."""
        if not self.size:
            return 0.0
        inv = 1.0 / np.sqrt(self.d2)
        if isinstance(self.M, Gram):
            return float(self.M.abs_row_sums(inv).max())
        Mt = sp.diags(inv) @ abs(self.M) @ sp.diags(inv)
        return float(np.asarray(Mt.sum(axis=1)).max())

    @property
    def empty(self) -> bool:
        """No unknown, or ``M = 0`` (nothing can move)."""
        if self.size == 0:
            return True
        if isinstance(self.M, Gram):
            return self.M.A.nnz == 0 or not np.any(self.M.A.data)
        return self.M.nnz == 0

    def explicit(self) -> sp.csr_matrix:
        """``M`` formed."""
        return explicit(self.M)

    def lambda_floor(self) -> float:
        """Smallest lambda whose solution is numerically meaningful (:data:`LAMBDA_FLOOR`)."""
        return LAMBDA_FLOOR * max(self.mu_bound(), 1e-300)

    def lambda_ceiling(self, tau: float) -> float:
        """``||c||_F / sqrt(tau)``: ``phi(lambda) <= ||c||^2 / lambda^2 <= tau`` above it."""
        return float(np.linalg.norm(self.r / np.sqrt(self.d2)[:, None]) / np.sqrt(tau))


def make_solver(
    system: SmoothingSystem, solver: SolverChoice, *, reuse: bool = True, symbolic: object = None
) -> LinearSolver:
    """The linear solver named ``solver`` for ``K(lambda) = M + lambda D^2``."""
    if solver == "cg":
        return MatrixFree(system.M, system.d2)
    return Direct(system.M, system.d2, solver, reuse=reuse, symbolic=symbolic)


class Deviation:
    """``phi(lambda)`` of a :class:`SmoothingSystem` (eq. 15), the shape of a root finder's ``F``.

    Parameters
    ----------
    system : SmoothingSystem
    solver : {"cholmod", "superlu", "cg"} or LinearSolver
        Solver name, or a solver already set up for ``system.M`` (shares its analysis).
    order : int
        Iterated Tikhonov order ``k >= 1``.
    reuse : bool
        Reuse a factorization at nearby lambdas (see :class:`service.core.linalg.solver.Direct`).
    symbolic : callable, optional
        Analysis cache hook for CHOLMOD.

    Attributes
    ----------
    history : list of (float, float)
        Every ``(lambda, phi)`` evaluated, in order.
    """

    def __init__(
        self,
        system: SmoothingSystem,
        *,
        solver: SolverChoice | LinearSolver = "cholmod",
        order: int = 1,
        reuse: bool = True,
        symbolic: object = None,
    ) -> None:
        if order < 1:
            raise ParameterError("order must be >= 1", field="params.order")
        self.system = system
        self.order = int(order)
        self.solver = (
            solver
            if isinstance(solver, LinearSolver)
            else make_solver(system, solver, reuse=reuse, symbolic=symbolic)
        )
        self.history: list[tuple[float, float]] = []
        self.listener: Callable[[float, float, int], None] | None = None
        self._E: dict[float, Array] = {}
        self._warm: dict[str, Array] = {}
        self.floor = system.lambda_floor()

    @property
    def stats(self) -> SolverStats:
        return self.solver.stats

    def use_matrix_free(self) -> None:
        """Switch to the matrix-free solver (work counted so far is kept)."""
        if isinstance(self.solver, MatrixFree):
            return
        stats = self.solver.stats
        self.solver = MatrixFree(self.system.M, self.system.d2)
        self.solver.stats = stats
        self._warm.clear()

    def adopt(self, lam: float, E: Array) -> None:
        """Take ``E`` as ``E_k(lam)``: computed elsewhere to a bound the caller checked (the one
        Lanczos run of issue 30, :mod:`service.core.search.one_run`), so that
        :meth:`deviation`, :meth:`value` and :meth:`solution` at ``lam`` need no solve; the
        solver becomes :class:`~service.core.linalg.solver.Lanczos` (work counted so far kept)."""
        stats = self.solver.stats
        self.solver = Lanczos(self.system.M, self.system.d2)
        self.solver.stats = stats
        self._warm.clear()
        self._E = {float(lam): E}

    def _solve(self, lam: float, R: Array, role: str, offset: Array | None = None) -> Array:
        X = self.solver.solve(lam, R, self._warm.get(role), offset)
        self._warm[role] = X
        return X

    def deviation(self, lam: float) -> Array:
        """``E_k(lambda) = U(lambda) - U0`` (``k`` solves with one factorization).

        ``U_1 = K^-1 (b + lambda D^2 U0)`` (no null-space component of ``M`` is amplified at
        small lambda, unlike ``K^-1 r``), then ``E_{j+1} = E_j - lambda K^-1 D^2 E_j``
        (``= K^-1 M E_j``).
        """
        if lam in self._E:
            return self._E[lam]
        if not lam >= self.floor:
            raise ParameterError(
                f"lambda={lam:.3g} is below {self.floor:.3g}, the smallest value for which the "
                "solution is numerically meaningful for this input",
                field="params.lam",
            )
        s = self.system
        d2 = s.d2[:, None]
        E = self._solve(lam, s.b + lam * d2 * s.U0, "U1", offset=s.U0) - s.U0
        for j in range(1, self.order):
            E = E - lam * self._solve(lam, d2 * E, f"Z{j + 1}")
        self._E = {lam: E}
        return E

    def solution(self, lam: float) -> Array:
        """``U(lambda) = U0 + E_k(lambda)``."""
        return self.system.U0 + self.deviation(lam)

    def value(self, lam: float) -> float:
        """``phi(lambda)`` without recording it in :attr:`history`."""
        E = self.deviation(lam)
        return float(np.sum(self.system.d2[:, None] * E**2))

    def __call__(self, lam: float) -> float:
        """``phi(lambda)``, recorded in :attr:`history` and reported to :attr:`listener`."""
        phi = self.value(lam)
        self.history.append((float(lam), phi))
        if self.listener is not None:
            self.listener(float(lam), phi, len(self.history))
        return phi

    def derivative(self, lam: float) -> float:
        """``phi'(lambda) = -2k <D^2 E_k, K^-1 D^2 E_k>`` (one more solve)."""
        W = self.system.d2[:, None] * self.deviation(lam)
        Z = self._solve(lam, W, "dphi")
        return float(-2.0 * self.order * np.sum(W * Z))

    def phi0(self) -> float:
        """``phi(0)``: the closed form when the system has one, else ``phi`` at the floor."""
        if self.system.phi0 is not None:
            return self.system.phi0
        return self.value(self.floor)

    def local_root(self, lam: float, tau: float, lo: float, hi: float) -> float | None:
        """Root of ``phi = tau`` in ``[lo, hi]`` from the factorization made at ``lam``.

        Shift-invert Lanczos with the factor of ``K(lam)`` (one solve per step,
        :func:`~service.core.linalg.krylov.shift_invert`) until the model's root lies inside the
        bracket and is stable to 1e-7. Below ``lam`` the model's Gauss rule underestimates
        ``phi`` (every derivative of ``theta^2 / (1 + delta theta)^2`` is positive for
        ``delta < 0``), so an unconverged root is still a lower bound of ``lambda*``. The
        Galerkin vectors at the root seed the next solves. ``None`` without a factorization
        at ``lam`` (matrix-free path).
        """
        solver = self.solver
        if not isinstance(solver, Direct) or solver.lam_factored != lam:
            return None
        s = self.system
        d = np.sqrt(s.d2)[:, None]
        roots: list[float] = []

        def stop(model: ShiftInvert) -> bool:
            if len(model.basis) < 2:
                return False
            roots.append(log_bisect(model.phi, tau, lo, hi))
            inside = lo < roots[-1] < hi
            return inside and len(roots) >= 2 and abs(roots[-1] - roots[-2]) <= 1e-7 * roots[-1]

        model, _ = shift_invert(
            lambda V: d * solver.apply_factor(d * V), s.r / d, lam, self.order, 20, stop
        )
        if not roots:
            return None
        self._seed(model, roots[-1], d)
        return roots[-1]

    def _seed(self, model: ShiftInvert, lam: float, d: Array) -> None:
        """Warm starts at ``lam`` for every solve of :meth:`deviation` and :meth:`derivative`.

        In the basis of ``S`` (``theta = 1 / (mu + lambda_0)``): ``D E_1`` is
        ``theta / (1 + delta theta)`` and ``D Z_{j+1} = (M_t + lambda)^-1 D E_j`` is
        ``(1 - lambda_0 theta)^(j-1) theta^2 / (1 + delta theta)^(j+1)`` applied to ``c``.
        """
        lam0 = model.lam0
        U0 = self.system.U0
        self._warm["U1"] = U0 + model.vector(lam, lambda t, dl: t / (1 + dl * t)) / d
        for j in range(1, self.order + 1):
            role = f"Z{j + 1}" if j < self.order else "dphi"

            def h(t: Array, dl: float, j: int = j) -> Array:
                return (1 - lam0 * t) ** (j - 1) * t**2 / (1 + dl * t) ** (j + 1)

            self._warm[role] = model.vector(lam, h) / d

    def reweighted(self, d2: Array) -> Deviation:
        """The same system with ``D^2 = diag(d2)``: same pattern, so no new analysis."""
        s = self.system
        system = SmoothingSystem(s.M, d2, s.b, s.U0)
        solver = self.solver
        new: LinearSolver = (
            solver.with_weights(system.d2) if isinstance(solver, Direct) else MatrixFree(s.M, d2)
        )
        return Deviation(system, solver=new, order=self.order)
