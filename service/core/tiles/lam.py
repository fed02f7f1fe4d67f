"""The one lambda of a tiled run, decided once and applied to every tile.

At a fixed lambda (input frame) the tiled solve is the untiled one up to the halos' truncation,
so a tiled run needs one decision: that lambda. It is a pluggable call,
``rule(probe, params, run_tile) -> LambdaDecision``: the coordinator hands it the probe tile (the
core nearest the input's centre, with a provisional halo) and a function that runs the default
on a tile (``lam=None``: the untiled rule there) and gets back the lambda and, when the rule
solved the probe at that lambda, its solution (reused, not solved again).

:func:`probe_rule` is today's rule: the untiled automatic rule (the risk minimiser of issue 37 with
the one global noise estimate and the data weights) run on the probe tile, whose lambda is
the run's; a given tau becomes the probe's share ``tau * sum_tile omega^2 /
sum omega^2``, ``rms`` stays per point, a given lambda is taken as it is. A rule that reads
every tile's curves (the whole input's risk, issue 43's open item) drops in as another
function of this shape.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.tiles.solve import TileSolution

__all__ = ["LambdaDecision", "LambdaRule", "ProbeTile", "probe_rule"]


@dataclass(frozen=True)
class ProbeTile:
    """The tile the rule looks at: its geometry (core first), core size and weight share.

    Attributes
    ----------
    geometry : Geometry
    n_core : int
    share : float
        ``sum_tile omega_i^2 / sum_all omega_i^2`` over the free points (a tau's share; the
        tile's phi counts its halo).
    """

    geometry: Geometry
    n_core: int
    share: float


@dataclass(frozen=True)
class LambdaDecision:
    """The run's lambda (input frame; ``None``: nothing to smooth), how it was decided, and the
    probe's solution at it when the rule made one."""

    lam: float | None
    how: str
    probe: TileSolution | None = None


#: ``run_tile(geometry, n_core, params, lam)``: the default on one tile (``lam=None``: its rule),
#: with the numbers the halo needs.
RunTile = Callable[[Geometry, int, SmoothingParams, "float | None"], TileSolution]
#: ``rule(probe, params, run_tile) -> LambdaDecision``.
LambdaRule = Callable[[ProbeTile, SmoothingParams, RunTile], LambdaDecision]


def probe_rule(probe: ProbeTile, params: SmoothingParams, run_tile: RunTile) -> LambdaDecision:
    """Today's rule on the probe tile (module docstring)."""
    if params.tau_rule == "lam":
        assert params.lam is not None
        return LambdaDecision(float(params.lam), "given",
                              run_tile(probe.geometry, probe.n_core, params, float(params.lam)))
    local = params
    how = "the untiled rule on the probe tile"
    if params.tau_rule == "tau":
        assert isinstance(params.tau, float | int)
        local = params.model_copy(update={"tau": float(params.tau) * probe.share})
        how = f"tau's share {probe.share:.4g} met on the probe tile"
    sol = run_tile(probe.geometry, probe.n_core, local, None)
    if sol.unchanged:
        return LambdaDecision(None, "the probe tile's default left it unchanged", sol)
    return LambdaDecision(sol.lam, how, sol)
