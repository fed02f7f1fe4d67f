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
from service.core.geometry import Geometry
from service.core.noise.curves import TRACK_WEIGHTS_WHY
from service.core.noise.robust import SPREAD
from service.core.operator.boundary import ends_rule
from service.core.operator.build import resolve_weights
from service.core.params import SmoothingParams
from service.core.params.rules import (
    AUTO_NORMAL_MAX_CODIM,
    DEFAULT_DISPLACEMENT,
    boundary_mode,
    codimension_of,
    data_weight_gates,
    free_only,
)
from service.core.problem import is_track
from service.core.search.one_run_target import DENSE, ONE_RUN_FROM
from service.core.search.one_run_target import applies as one_run_applies
from service.core.system.displacement import resolve_displacement
from service.core.warnings import EngineWarning, warning

if TYPE_CHECKING:  # pragma: no cover
    from service.core.finish.outliers import Outliers
    from service.core.problem import Problem
    from service.core.search.target import Target

__all__ = ["Choice", "Plan", "make_plan", "with_finish", "with_problem", "with_solution"]

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
        The caller's parameters with displacement, weights, ends, boundary, outliers and the
        data weights' gates (``robust``, ``noise_weights``) resolved.
    displacement, ends, boundary, weights, data_weights, outliers, tangential, tau_rule, method,
    search, solver : Choice
    warnings : tuple of EngineWarning
        What the user should hear of a decision (given weights shut the data weights' gates).
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
    warnings: tuple[EngineWarning, ...] = ()

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
    r = codimension_of(geometry.kind, geometry.dim)
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
    params: SmoothingParams, geometry: Geometry, displacement: str, tracks: bool = True
) -> tuple[Choice, Choice, Choice]:
    """Neighbour weights (eq. 1, sections 4.2-4.4), curve ends and mesh boundary rows (for the
    resolved ``displacement``: :func:`~service.core.params.rules.boundary_mode`)."""
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
    rule = "ring" if geometry.faces is None else boundary_mode(params.boundary, displacement)
    if geometry.faces is None:
        why = "no mesh boundary: the rule does not apply"
    elif params.boundary != "auto":
        why = _given(params, "boundary")
    elif rule == "curve":
        why = "'curve': the points move freely (free displacement)"
    else:
        why = "'ring': with normal displacement the boundary curve's own curvature stays"
    boundary = Choice(rule, why, {"mesh": geometry.faces is not None, "displacement": displacement})
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


def _data_weights(params: SmoothingParams, geometry: Geometry) -> tuple[Choice, str, str]:
    """The data weights' gates (issue 21): the robust rule and the noise weights the run tries
    (:func:`~service.core.params.rules.data_weight_gates`); what they applied completes the
    choice once the problem is set up (:func:`with_problem`)."""
    user = geometry.weights is not None
    robust, noise = data_weight_gates(params.robust, params.noise_weights, params.tau_rule, user)
    evidence = {"robust": robust, "noise_weights": noise, "tau_rule": params.tau_rule,
                "user_weights": user}  # fmt: skip
    tried = [name for name, rule in (("robust", robust), ("noise", noise)) if rule != "none"]
    if tried:
        return Choice(" + ".join(tried), "tried: " + " and ".join(tried) + " weights", evidence), \
            robust, noise  # fmt: skip
    if user and "auto" in (params.robust, params.noise_weights):
        why = "weights given: the automatic robust and noise weights do not override them"
    elif params.tau_rule != "auto" and "auto" in (params.robust, params.noise_weights):
        why = "a given tau, rms or lambda is a budget in the user's weights"
    else:
        why = "robust='none' and noise_weights='none'"
    return Choice("none", why, evidence), robust, noise


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
    weights, ends, boundary = _operator_choices(params, geometry, resolved.displacement, tracks)
    outliers = _outliers(params, geometry)
    data, robust, noise = _data_weights(params, geometry)
    resolved = resolved.model_copy(update={
        "weights": weights.value, "ends": ends.value, "boundary": boundary.value,
        "outliers": outliers.value, "robust": robust, "noise_weights": noise,
    })  # fmt: skip
    said: tuple[EngineWarning, ...] = ()
    if data.value == "none" and data.why.startswith("weights given"):
        said = (warning("data-weights-not-applied", "weights given: no automatic robust or noise "
                        "weights (robust='huber' or 'tukey', noise_weights='local' apply them on "
                        "top)"),)  # fmt: skip
    track = params.tau_rule == "auto" and is_track(geometry, params.tau_rule)
    tau_rule, method, search, solver = _budget_choices(params, track)
    return Plan(
        params=resolved,
        displacement=_displacement(params, geometry, resolved.displacement),
        ends=ends,
        boundary=boundary,
        weights=weights,
        data_weights=data,
        outliers=outliers,
        tangential=_tangential(resolved, geometry),
        tau_rule=tau_rule,
        method=method,
        search=search,
        solver=solver,
        warnings=said,
    )


def _tangential(params: SmoothingParams, geometry: Geometry) -> Choice:
    """The tangential step (issue 21, :mod:`service.core.finish.tangential`): for triangle
    meshes in 3-D smoothed by normal displacement with the automatic tau and
    ``tangential="auto"`` (an explicit ``displacement="normal"`` turns it off,
    :func:`~service.core.system.displacement.resolve_displacement`); a given tau, rms or lambda
    keeps its contract ``phi = tau``. ``params``: displacement resolved."""
    evidence = {"displacement": params.displacement, "tau_rule": params.tau_rule,
                "mesh_3d": geometry.faces is not None and geometry.dim == 3,
                "method": params.method}  # fmt: skip
    if params.tangential == "off":
        return Choice("off", _given(params, "tangential"), evidence)
    on = (
        params.tau_rule == "auto"
        and params.displacement == "normal"
        and bool(evidence["mesh_3d"])
        and params.method == "tikhonov"
    )
    if on:
        return Choice("on", "normal displacement of a 3-D mesh with the automatic tau", evidence)
    return Choice("off", "applies to normal displacement of 3-D meshes with the automatic tau "
                  "only", evidence)  # fmt: skip


def with_problem(plan: Plan, problem: Problem) -> Plan:
    """The plan completed with what setting up the problem decided: the displacement that
    was used (``"auto"`` falls back to free for an input flat across itself) and what the data
    weights applied (:func:`service.core.noise.robust.data_weights`)."""
    displacement = plan.displacement
    tangential = plan.tangential
    if problem.params.displacement != displacement.value:
        displacement = Choice(
            problem.params.displacement,
            "free: nothing moves along the normals (the input is smooth across itself)",
            displacement.evidence,
        )
        tangential = _tangential(problem.params, problem.geometry)
    dw = problem.weights
    evidence = dict(plan.data_weights.evidence)
    if dw is None or (dw.robust == "none" and not dw.uneven):
        value = "none"
        why = plan.data_weights.why if plan.data_weights.value == "none" else \
            "no outliers found and the noise is even: the user's weights only"  # fmt: skip
    else:
        value = " + ".join(["robust"] * (dw.robust != "none") + ["noise"] * dw.uneven)
        why = "robust weights for outliers, noise weights for uneven noise (issue 21)"
    if dw is not None:
        evidence.update(rule=dw.robust, outliers_found=int(dw.outliers.size),
                        log_sigma_spread=dw.spread, spread_gate=SPREAD)  # fmt: skip
    data = Choice(value, why, evidence)
    return replace(plan, displacement=displacement, data_weights=data, tangential=tangential,
                   search=_search(plan, problem))


def _search(plan: Plan, problem: Problem) -> Choice:
    """The lambda search decided for this system (issue 37): how the automatic rule reads
    its curves, or how a given tau is met, by the unknowns and the parameters."""
    if plan.search.value != "auto":
        return plan.search
    size = problem.system.size
    evidence = {"unknowns": size, "dense_up_to": DENSE, "one_run_from": ONE_RUN_FROM}
    one = one_run_applies(problem.params, size)
    if plan.tau_rule.value == "risk":
        if size <= DENSE:
            return Choice("risk-exact", "the risk's minimiser from the exact spectrum of M_t "
                          "(no probes)", evidence)
        if not one:
            return Choice("risk-polished", "a short Lanczos run with probes, then the exact "
                          "minimisers by Brent's method on the factorization's derivatives",
                          evidence)
        return Choice("risk-one-run", "lambda* decided on the converged curves of the one "
                      "Lanczos run (with probes), which then gives the solution", evidence)
    if one and plan.tau_rule.value != "gcv":
        return Choice("one-run", "the root of phi = tau and the solution from one Lanczos run",
                      evidence)
    if plan.tau_rule.value == "gcv":
        return Choice("gcv", "Brent's method on the GCV score (probes solved with the factor)",
                      evidence)
    return Choice("newton", "safeguarded Newton on phi^(-1/2k) with local root proposals",
                  evidence)


def with_finish(plan: Plan, outliers: Outliers | None) -> Plan:
    """The plan completed with the outliers the finish stage reports (one record,
    :class:`~service.core.finish.outliers.Outliers`; ``None``: no data weights, none): the
    report's ``outlier_count`` is this ``count``."""
    numbers = {"count": 0, "found": 0}
    if outliers is not None:
        numbers = {"count": outliers.count, "found": outliers.found, "moved_far": outliers.far,
                   "within_noise": outliers.within_noise}  # fmt: skip
    evidence = {**plan.outliers.evidence, **numbers}
    return replace(plan, outliers=replace(plan.outliers, evidence=evidence))


def with_solution(
    plan: Plan, target: Target, solver: str, warnings: tuple[EngineWarning, ...]
) -> Plan:
    """The plan completed after the solve: the target the run met (knee, GCV) and the
    solver path taken (with the reasons its ``"matrix-free"`` warnings give)."""
    evidence: dict[str, Any] = {"tau": target.tau, "sigma": target.sigma,
                                **(target.evidence or {})}  # fmt: skip
    tau_rule = replace(plan.tau_rule, evidence=evidence)
    reasons = [
        w.message
        for w in warnings
        if w.code == "matrix-free" or w.message.startswith("matrix-free path")  # search's
    ]
    if plan.solver.value != "auto":
        why = plan.solver.why
    elif solver == "none":
        why = "no system solved"
    elif solver == "lanczos":
        why = "one Lanczos run: lambda and the solution without a factorization"
    else:
        why = "; ".join(reasons) or "direct: nothing selected the matrix-free path"
    return replace(plan, tau_rule=tau_rule, solver=Choice(solver, why, plan.solver.evidence))
