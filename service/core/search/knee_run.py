"""The automatic tau's knee, decided on the one Lanczos run of the default path (issue 30).

The knee (:func:`service.core.search.autotau.knee_tau`) is the flattest point of ``log phi``
against ``log lambda`` in ``KNEE_WINDOW x tau0``. On the recurrence of
:mod:`service.core.search.one_run` it is read from the Gauss model of ``phi`` at every
checkpoint (:func:`converged_knee`) and decided from converged quantities only:

* **a knee**: the Gauss model's knee, where its ``phi`` agrees with the Gauss-Radau model's
  within :data:`KNEE_PHI_RTOL`, at two checkpoints in a row (about 10 % of the steps apart)
  with tau within ``KNEE_RTOL / 10``: decided, at the later tau (the readings drift while the
  model converges, ~0.2 % per 10 % of the steps at first: 0.25 % let the 100K torus decide at
  180 steps, 0.6 % below its knee; 0.1 % decides at 260, 0.13 % below). For order 1 the two rules
  bracket the exact ``phi`` (Golub and Meurant); for order ``k > 1`` the Radau rule is no
  bound, but it converges to the same ``phi``: agreement still means convergence.
* **no knee**: the whole window has converged (both models agree on every grid point, its
  lower end above the floor) and holds no interior maximum of the slope.
* at the cap (:data:`KNEE_CAP` steps or half the unknowns): the knee if ``phi`` has converged
  there, else none (a cost bound: deeper knees, as the 1M torus's, are not looked for).

Why not the old rule (the geometric mean of the two models at 40, 60, ... 400 steps, decided
when stable or at 400): a model of ``j`` steps resolves ``phi`` down to ``lambda ~ mu_max /
j^2`` only, and these knees are deep: the 1M torus of the speed benchmark has its knee at 1.055
tau0, lambda ~ 1e-5, which the Gauss model first shows at 600 steps; the old rule stopped at its
cap and answered "no knee" (the target stayed at tau0). Measured (Gauss model, 164K icosphere /
1M torus): decided at 420 / 660 steps at 1.0701 / 1.0537 tau0, the 1800- / 800-step models'
knees 1.0705 / 1.0548 (converged: 1.055); 100K torus (550 x 183) at 260 steps, 1.0091 (1600
steps: 1.0104). A rigorous rule (the set of grid points whose slope,
within the error the models' gap allows, could still be the largest, and the spread of their
``phi``) needs ``phi`` to ~1e-5 around the knee on these flat knees: 1500 steps at 164K.

**The target** (:func:`knee_target`): ``(1 - KNEE_RTOL)`` times the knee's tau, the smallest
tau within the knee's resolution. A knee is flat by definition: on those inputs
``d log phi / d log lambda`` is -0.006 / -0.0025 there, so 1 % of tau is a factor 4-10 in
lambda, and the solve costs ``O(sqrt(mu_max / lambda))`` steps: 1 % below the knee it takes
half the steps (164K: 600 instead of 1300), and its distance to the true surface was no worse
(164K: 2.70e-4 at 1.060 tau0, 2.67e-4 at 1.065, 2.79e-4 at the knee 1.070; 1M: 6.2e-5 at
1.040 tau0, 1.03e-4 at tau0, the old rule's answer).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from service.core.linalg.lanczos_run import LanczosRun, TikhonovModel
from service.core.search.autotau import KNEE_WINDOW, _flattest

__all__ = [
    "KNEE_CAP",
    "KNEE_GRID",
    "KNEE_PHI_RTOL",
    "KNEE_RTOL",
    "KneeRule",
    "converged_knee",
    "knee_target",
]

Array = NDArray[np.float64]
KNEE_GRID = 240
#: The knee's resolution in tau (log of the ratio): two checkpoints agree within half of it,
#: and the target lies this far below the knee.
KNEE_RTOL = 1e-2
#: Agreement of the Gauss and Gauss-Radau ``phi`` where the knee rule trusts the model.
KNEE_PHI_RTOL = 1e-3
#: Steps after which the knee is decided on what has converged, else none (the target stays
#: tau0). A cost bound, chosen for speed (issue 30): the 1M torus's knee first shows at ~650
#: steps; with the cap at 2000 its default took 1010 products, 37.5 s CPU (surface error
#: 5.3e-5), at 400 it takes 421 products, ~12 s for the run (surface error 1.01e-4, Open3D's
#: 1.41e-4); the 164K icosphere decides within the cap either way.
KNEE_CAP = 400


def knee_target(knee: float) -> float:
    """The target on a knee's tau: :data:`KNEE_RTOL` below it (module docstring)."""
    return knee * (1.0 - KNEE_RTOL)


def converged_knee(
    model: TikhonovModel, tau0: float, lo: float, ceiling: Callable[[float], float]
) -> tuple[float | None, bool, bool]:
    """``(tau at the Gauss model's knee or None, whether phi has converged there, whether it
    has converged over the whole window)`` (module docstring)."""
    lo_tau, hi_tau = KNEE_WINDOW[0] * tau0, KNEE_WINDOW[1] * tau0
    hi = max(ceiling(lo_tau), lo)
    lam_hi, lam_lo = model.root(lo_tau, lo, hi), model.root(hi_tau, lo, hi)
    if not lam_lo < lam_hi:
        return None, False, False
    grid = np.geomspace(lam_lo, lam_hi, KNEE_GRID)
    gauss = np.maximum(model.phi(grid), 1e-300)
    gap = np.abs(np.log(np.maximum(model.phi(grid, radau=True), 1e-300) / gauss))
    ok = gap <= KNEE_PHI_RTOL
    whole = bool(ok.all()) and lam_lo > lo * (1 + KNEE_RTOL)
    i = _flattest(grid, gauss)
    if i is None:
        return None, False, whole
    return float(gauss[i]), bool(ok[i]), whole


class KneeRule:
    """The knee over the checkpoints of one run (module docstring).

    Parameters
    ----------
    tau0 : float
        The discrepancy estimate (internal frame).
    lo : float
        The lambda floor.
    ceiling : callable
        ``tau -> ||c||_F / sqrt(tau)`` (``SmoothingSystem.lambda_ceiling``).
    size : int
        Unknowns (the cap is half of them, at most :data:`KNEE_CAP`).
    """

    def __init__(
        self, tau0: float, lo: float, ceiling: Callable[[float], float], size: int
    ) -> None:
        self.tau0, self.lo, self.ceiling = tau0, lo, ceiling
        self.cap = max(40, min(KNEE_CAP, size // 2))
        self.last: float | None = None
        self.how = ""

    def update(
        self, run: LanczosRun, model: TikhonovModel
    ) -> tuple[bool, float | None]:  # fmt: skip
        """``(decided, tau at the knee or None)`` after the steps done (``how`` says why)."""
        tau, converged, whole = converged_knee(model, self.tau0, self.lo, self.ceiling)
        last, self.last = self.last, (tau if converged else None)
        if (
            tau is not None
            and last is not None
            and converged
            and abs(math.log(tau / last)) <= KNEE_RTOL / 10
        ):
            self.how = f"converged at {run.steps} steps"
            return True, tau
        if tau is None and whole:
            self.how = f"none: the window converged at {run.steps} steps"
            return True, None
        if run.steps >= self.cap or run.done:
            self.how = f"at the cap of {run.steps} steps"
            return True, tau if converged else None
        return False, None
