"""The automatic tau's knee, decided on the one Lanczos run of the default path (issue 30).

The knee (:func:`service.core.search.autotau.knee_tau`) is the flattest point of ``log phi``
against ``log lambda`` in ``KNEE_WINDOW x tau0``. Two rules decide it on the recurrence of
:class:`~service.core.search.one_run` (whichever decides first):

* **converged** (:func:`converged_knee`): the knee taken from the Gauss and from the Gauss-Radau
  model separately; both find one and their ``phi`` there agree within :data:`KNEE_RTOL` (the
  target is what the knee decides: on a plateau its lambda is ill-determined, its tau is not),
  or neither finds one while both put the window's ends at the same lambdas, above the floor.
  For order ``k > 1`` the Radau rule is no upper bound, but it converges to the same ``phi``:
  agreement still means convergence.
* **stable** (:class:`KneeRule`): the old rule's model, the geometric mean of the two models
  (:func:`service.core.linalg.krylov._models`) on the Gauss model's window, at the old rule's
  checkpoints (40, 60, 90, 135, 200, 300 steps): decided when its knee's tau stayed within 1 %
  over three checkpoints in a row, and at the cap (400 steps, or half the unknowns) by that
  model whatever it says. The old rule also gave up ("no knee") after two checkpoints in a row
  without one from the fourth on, and stopped when the knee's lambda moved less than 1 %: both
  decisions flip under rounding-level changes of the system (164K icosphere: the knee at
  1.070 tau0 that the models converge to from 400 steps on, or none at 135 steps, depending on
  the last bits of the data weights; 1M torus: the models converge to a knee at 1.055 tau0
  (600 steps), the mean model reads 1.051, 1.054, 1.059 at 135, 200, 300 steps and none at
  400, the old rule's answer), so "no knee" is now decided only from converged models or at
  the cap, and a knee only when it held still over three checkpoints (two agreed by chance).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from service.core.linalg.krylov import Quadrature, _models
from service.core.linalg.lanczos_run import LanczosRun, TikhonovModel
from service.core.search.autotau import KNEE_CHECKPOINTS, KNEE_STEPS, KNEE_WINDOW, _flattest

__all__ = ["KNEE_GRID", "KNEE_RTOL", "KneeRule", "converged_knee"]

Array = NDArray[np.float64]
KNEE_GRID = 240
#: Agreement of the Gauss and the Radau model's knee (log of the tau ratio) that decides it.
KNEE_RTOL = 1e-2


def converged_knee(
    model: TikhonovModel, tau0: float, lo: float, ceiling: Callable[[float], float]
) -> tuple[bool, float | None]:
    """``(decided, tau at the knee or None)`` by the converged rule (module docstring)."""
    lo_tau, hi_tau = KNEE_WINDOW[0] * tau0, KNEE_WINDOW[1] * tau0
    hi = ceiling(lo_tau)
    knees: list[tuple[float | None, float, float]] = []
    for radau in (False, True):
        lam_hi, lam_lo = model.root(lo_tau, lo, hi, radau), model.root(hi_tau, lo, hi, radau)
        if not lam_lo < lam_hi:
            knees.append((None, lam_lo, lam_hi))
            continue
        grid = np.geomspace(lam_lo, lam_hi, KNEE_GRID)
        phis = np.maximum(model.phi(grid, radau), 1e-300)
        i = _flattest(grid, phis)
        knees.append((None if i is None else float(phis[i]), lam_lo, lam_hi))
    (tg, glo, ghi), (tr, rlo, rhi) = knees
    if tg is not None and tr is not None:
        return abs(math.log(tg / tr)) <= KNEE_RTOL, math.sqrt(tg * tr)
    window = abs(math.log(glo / rlo)) <= KNEE_RTOL and abs(math.log(ghi / rhi)) <= KNEE_RTOL
    inside = min(glo, rlo) > lo * (1 + KNEE_RTOL)  # resolved above the floor
    return tg is None and tr is None and window and inside, None


def _old_knee(
    gauss: Quadrature, radau: Quadrature, tau0: float, lo: float,
    ceiling: Callable[[float], float],
) -> float | None:  # fmt: skip
    """The lambda of the old rule's knee for one pair of models (``knee_tau``'s inner step)."""
    lo_tau, hi_tau = KNEE_WINDOW[0] * tau0, KNEE_WINDOW[1] * tau0
    hi = max(ceiling(lo_tau), lo)
    lam_hi, lam_lo = gauss.root(lo_tau, lo, hi), gauss.root(hi_tau, lo, hi)
    if not lam_lo < lam_hi:
        return None
    grid = np.geomspace(lam_lo, lam_hi, KNEE_GRID)
    phi = np.array([math.sqrt(max(gauss.phi(x), 1e-300) * max(radau.phi(x), 1e-300))
                    for x in grid])  # fmt: skip
    i = _flattest(grid, phi)
    return None if i is None else float(grid[i])


class KneeRule:
    """Both rules over the checkpoints of one run (module docstring).

    Parameters
    ----------
    tau0 : float
        The discrepancy estimate (internal frame).
    lo : float
        The lambda floor.
    ceiling : callable
        ``tau -> ||c||_F / sqrt(tau)`` (``SmoothingSystem.lambda_ceiling``).
    size : int
        Unknowns (the cap is half of them, at most ``KNEE_STEPS[1]``).
    order : int
        Iterated Tikhonov order.
    """

    def __init__(
        self, tau0: float, lo: float, ceiling: Callable[[float], float], size: int, order: int
    ) -> None:
        self.tau0, self.lo, self.ceiling, self.order = tau0, lo, ceiling, order
        self.cap = max(KNEE_STEPS[0], min(KNEE_STEPS[1], size // 2))
        self.checkpoints = [j for j in KNEE_CHECKPOINTS if j < self.cap] + [self.cap]
        self.seen: list[float | None] = []
        self.how = ""

    def wants(self, steps: int) -> bool:
        """Whether the stable rule looks at the models after ``steps`` steps."""
        return steps in self.checkpoints

    def update(
        self, run: LanczosRun, model: TikhonovModel
    ) -> tuple[bool, float | None]:  # fmt: skip
        """``(decided, tau at the knee or None)`` after the steps done (``how`` says which
        rule decided)."""
        decided, tau = converged_knee(model, self.tau0, self.lo, self.ceiling)
        if decided:
            self.how = f"converged at {run.steps} steps"
            return True, tau
        if not (self.wants(run.steps) or run.done):
            return False, None
        gauss, radau = _models(*run.live_coefficients(), self.order)
        lam = _old_knee(gauss, radau, self.tau0, self.lo, self.ceiling)
        tau = None if lam is None else math.sqrt(gauss.phi(lam) * radau.phi(lam))
        self.seen.append(tau)
        last = [t for t in self.seen[-3:] if t is not None]
        stable = len(last) == 3 and math.log(max(last) / min(last)) < 0.01
        if stable:
            self.how = f"stable at {run.steps} steps"
            return True, tau
        if run.steps >= self.cap or run.done:
            self.how = f"at the cap of {run.steps} steps"
            return True, tau
        return False, None
