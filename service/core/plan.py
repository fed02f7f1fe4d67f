"""The :class:`Plan` of a run: every automatic choice, decided once, with its evidence.

:func:`make_plan` decides before anything is built what the parameters and the input alone
decide (displacement mode, curve ends, mesh boundary rows, neighbour weights, the tau rule,
method and lambda search) and returns the parameters with those ``"auto"`` values resolved
(:attr:`Plan.params`), which every later stage reads. What only a later stage can know
completes the plan as a new record: the data weights and the tangential step once the problem
is set up (:func:`with_problem`), the target once the knee or GCV moved it and the solver path
once the system was solved (:func:`with_solution`). The report carries :meth:`Plan.to_dict`
(``plan``): for each choice its value, why, and the evidence.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from service.core.errors import ParameterError
from service.core.finish.tangential import applies as tangential_applies
from service.core.geometry import Geometry
from service.core.noise.curves import TRACK_WEIGHTS_WHY
from service.core.noise.estimate import codimension
from service.core.operator.boundary import boundary_rule, ends_rule
from service.core.operator.build import resolve_weights
from service.core.params import SmoothingParams
from service.core.params.rules import DEFAULT_DISPLACEMENT, free_only
from service.core.problem import is_track
from service.core.system.displacement import AUTO_NORMAL_MAX_CODIM, resolve_displacement

if TYPE_CHECKING:  # pragma: no cover
    from service.core.problem import Problem
    from service.core.search.target import Target

__all__ = ["Choice", "Plan", "make_plan", "with_problem", "with_solution"]

CHOICES = (
    "displacement",
    "ends",
    "boundary",
    "weights",
    "data_weights",
    "outliers",
    "tangential",
    "tau_rule",
    "method",
    "search",
    "solver",
)


@dataclass(frozen=True)
class Choice:
    """One decision: its value, why, and the numbers it was decided on."""

    value: Any
    why: str
    evidence: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "why": self.why, "evidence": dict(self.evidence)}


@dataclass(frozen=True)
class Plan:
    """Every automatic choice of a run (frozen; later stages return completed copies).

    Attributes
    ----------
    params : SmoothingParams
        The caller's parameters with displacement, weights, ends and boundary resolved.
    displacement, ends, boundary, weights, data_weights, outliers, tangential, tau_rule, method,
    search, solver : Choice
    """

    params: SmoothingParams
    displacement: Choice
    ends: Choice
    boundary: Choice
    weights: Choice
    data_weights: Choice
    outliers: Choice
    tangential: Choice
    tau_rule: Choice
    method: Choice
    search: Choice
    solver: Choice

    @property
    def automatic_tau(self) -> bool:
        """Whether the run chooses its own budget: the automatic rule (``"risk"``, issue 37)
        or, for a track with correlated noise, the discrepancy principle."""
        return bool(self.tau_rule.value in ("risk", "discrepancy"))

    def to_dict(self) -> dict[str, Any]:
        """The report's ``plan``: ``{choice: {"value", "why", "evidence"}}`` (JSON-ready)."""
        return {name: getattr(self, name).to_dict() for name in CHOICES}


def _given(params: SmoothingParams, name: str) -> str:
    """``"given"`` or ``"default"``: how a value that is not ``"auto"`` was set."""
    return "given" if name in params.model_fields_set else "default"


def _displacement(params: SmoothingParams, geometry: Geometry, mode: str) -> Choice:
    r = codimension(geometry)
    evidence = {"kind": geometry.kind, "dim": geometry.dim, "normal_directions": r}
    if params.displacement != "auto":
        return Choice(mode, _given(params, "displacement"), evidence)
    if free_only(params.method, params.tau_rule):
        why = "free: windowed-sinc and tau='gcv' filter the points themselves"
    elif mode != DEFAULT_DISPLACEMENT[geometry.kind]:
        why = f"free: normal displacement only with 1 to {AUTO_NORMAL_MAX_CODIM} normal directions"
    else:
        why = f"the quality benchmark's choice for a {geometry.kind}"
    return Choice(mode, why, evidence)


def _operator_choices(
    params: SmoothingParams, geometry: Geometry, tracks: bool = True
) -> tuple[Choice, Choice, Choice]:
    """Neighbour weights (eq. 1, sections 4.2-4.4), curve ends and mesh boundary rows."""
    triangles = geometry.kind == "mesh" or (
        geometry.kind == "cloud" and params.neighborhood == "delaunay"
    )
    scheme = resolve_weights(params, geometry)
    weights = Choice(
        scheme,
        _given(params, "weights") if params.weights != "auto" else
        "the report's: mean value with triangles (4.3-4.4), reciprocal distance otherwise (4.2)",
        {"kind": geometry.kind, "triangles": triangles},
    )  # fmt: skip
    if tracks and "weights" not in params.model_fields_set and is_track(geometry, params.tau_rule):
        weights = Choice("reciprocal", TRACK_WEIGHTS_WHY, weights.evidence)
    open_ends = geometry.edges is not None and geometry.faces is None
    if not open_ends:
        ends_why = "no open polylines: the rule does not apply"
    elif params.ends != "auto":
        ends_why = _given(params, "ends")
    else:
        ends_why = "fixed in place, as VTK's polyline smoothing"
    ends = Choice(ends_rule(params), ends_why, {"applies": open_ends})
    rule = boundary_rule(params, geometry)
    if geometry.faces is None:
        why = "no mesh boundary: the rule does not apply"
    elif params.boundary != "auto":
        why = _given(params, "boundary")
    else:
        why = "'curve' where points move freely, 'ring' with normal displacement"
    boundary = Choice(rule, why, {"mesh": geometry.faces is not None})
    return weights, ends, boundary


def _outliers(params: SmoothingParams, geometry: Geometry) -> Choice:
    """What happens to outliers (issue 31): a cloud's stray point is usually not a noisy sample
    of the surface, so it is flagged and kept where it was; a mesh's or curve's spike is
    pulled back into its ring (bounded by the ring's reach). ``drop`` removes rows, which only
    a point cloud can lose without tearing connectivity.

    Raises
    ------
    ParameterError
        ``outliers="drop"`` on a mesh or a curve.
    """
    kind = geometry.kind
    evidence = {"kind": kind}
    if params.outliers == "drop" and kind != "cloud":
        raise ParameterError(
            f"outliers 'drop' removes points, which a {kind} cannot lose without tearing its "
            "connectivity; use 'flag' or 'pull'",
            field="params.outliers",
        )
    if params.outliers != "auto":
        return Choice(params.outliers, _given(params, "outliers"), evidence)
    if kind == "cloud":
        return Choice("flag", "a point cloud's stray point is not a noisy sample of the "
                      "surface: kept in place, flagged (as PDAL filters.outlier)", evidence)
    return Choice("pull", f"a {kind}'s spike is pulled back into its ring (eq. 4, omega -> 0), "
                  "no further than the ring reaches", evidence)


#: Why the automatic rule (issue 37; the comparison in service/core/README.md).
RISK_WHY = (
    "lambda minimising the unbiased predictive risk (Mallows C_L / Stein) with the larger of "
    "the local fits' and Wahba's noise estimates: within 1-4 % of the oracle lambda's error "
    "on the calibration half, where the discrepancy budget lost up to 3.5x and the knee up "
    "to 1.26x"
)
TRACK_WHY = (
    "a track's noise is correlated along it, which the risk estimate (white noise) does not "
    "model: the discrepancy budget of the track's own noise estimate (issue 31)"
)


def _budget_choices(
    params: SmoothingParams, track: bool
) -> tuple[Choice, Choice, Choice, Choice]:  # fmt: skip
    """The tau rule (eq. 3), the method, the lambda search (section 6.3), the solver."""
    rule: str = params.tau_rule
    if rule == "auto":
        rule = "discrepancy" if track else "risk"
    tau_why = {
        "lam": "lambda given",
        "tau": "tau given",
        "rms": "rms given: tau = rms^2 sum omega_i^2 over the free points",
        "gcv": "generalized cross-validation (tau = phi at its lambda)",
        "risk": RISK_WHY,
        "discrepancy": TRACK_WHY,
    }[rule]
    method = Choice(params.method, _given(params, "method"))
    if params.lam is not None or params.method == "windowed-sinc":
        search = Choice("none", "no lambda search (lambda given or windowed-sinc)")
    elif params.search == "auto":
        search = Choice("auto", "safeguarded Newton with local root proposals")
    else:
        search = Choice(params.search, _given(params, "search"))
    solver = Choice(params.solver, _given(params, "solver") if params.solver != "auto" else "")
    return Choice(rule, tau_why), method, search, solver


def make_plan(geometry: Geometry, params: SmoothingParams, tracks: bool = True) -> Plan:
    """Every choice the parameters and the input decide, before anything is built.

    ``tracks``: a track's own weights may be chosen (:data:`TRACK_WEIGHTS_WHY`); ``False``
    where an operator built from the caller's parameters is reused (tiles).

    Raises
    ------
    ParameterError
        An explicit choice the input cannot take (see :func:`resolve_displacement`,
        :func:`resolve_weights`).
    """
    resolved = resolve_displacement(params, geometry)
    weights, ends, boundary = _operator_choices(params, geometry, tracks)
    outliers = _outliers(params, geometry)
    resolved = resolved.model_copy(update={
        "weights": weights.value, "ends": ends.value, "boundary": boundary.value,
        "outliers": outliers.value,
    })  # fmt: skip
    track = params.tau_rule == "auto" and is_track(geometry, params.tau_rule)
    tau_rule, method, search, solver = _budget_choices(params, track)
    return Plan(
        params=resolved,
        displacement=_displacement(params, geometry, resolved.displacement),
        ends=ends,
        boundary=boundary,
        weights=weights,
        data_weights=Choice(None, "decided when the problem is set up"),
        outliers=outliers,
        tangential=Choice(None, "decided when the problem is set up"),
        tau_rule=tau_rule,
        method=method,
        search=search,
        solver=solver,
    )


def with_problem(plan: Plan, problem: Problem) -> Plan:
    """The plan completed with what setting up the problem decided: the displacement that
    was used (``"auto"`` falls back to free for an input flat across itself), the data
    weights (:func:`service.core.noise.robust.data_weights`) and the tangential step."""
    displacement = plan.displacement
    if problem.params.displacement != displacement.value:
        displacement = Choice(
            problem.params.displacement,
            "free: nothing moves along the normals (the input is smooth across itself)",
            displacement.evidence,
        )
    dw = problem.weights
    if dw is None:
        data = Choice(None, "the user's weights only (no robust or noise weights apply)")
    else:
        kinds = [f"robust ({dw.robust})"] if dw.robust != "none" else []
        kinds += ["noise"] if dw.uneven else []
        data = Choice(
            " + ".join(kinds) or None,
            "robust weights for outliers, noise weights for uneven noise (issue 21)",
            {"outliers": int(dw.outliers.size), "log_sigma_spread": dw.spread},
        )
    on = tangential_applies(problem.geometry, problem.params)
    tangential = Choice(
        "auto" if on else "off",
        "normal displacement of a 3-D mesh with the automatic tau" if on else
        ("off" if problem.params.tangential == "off" else "does not apply to this run"),
    )  # fmt: skip
    outliers = plan.outliers
    if dw is not None:
        outliers = replace(outliers, evidence={**outliers.evidence, "count": int(dw.outliers.size)})
    return replace(plan, displacement=displacement, data_weights=data, outliers=outliers,
                   tangential=tangential)


def with_solution(plan: Plan, target: Target, solver: str, notes: list[str]) -> Plan:
    """The plan completed after the solve: the target the run met (knee, GCV) and the
    solver path taken (with the reasons the path notes give)."""
    evidence: dict[str, Any] = {"tau": target.tau, "sigma": target.sigma,
                                **(target.evidence or {})}  # fmt: skip
    tau_rule = replace(plan.tau_rule, evidence=evidence)
    reasons = [note for note in notes if note.startswith("matrix-free path")]
    if plan.solver.value != "auto":
        why = plan.solver.why
    elif solver == "none":
        why = "no system solved"
    elif solver == "lanczos":
        why = "one Lanczos run: lambda and the solution without a factorization"
    else:
        why = "; ".join(reasons) or "direct: nothing selected the matrix-free path"
    return replace(plan, tau_rule=tau_rule, solver=Choice(solver, why, plan.solver.evidence))
