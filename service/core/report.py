"""The one model of a run's report: ``SmoothResult.report()`` member by member.

Every surface reads the report's shape from here: the HTTP API documents it with this model
(``service.api.schemas`` re-exports it, the OpenAPI component ``Report`` is generated from
it), the API's example is :func:`service.core.report.report_example`, and the Python
client's field list is generated from the OpenAPI document (``make openapi``). A test checks
that the members of ``SmoothResult.report()`` and the fields of
:class:`service.core.report.Report` are the same set.

Each field carries its type, description and examples; where a member has another spelling
it is an alias (docs/names.md): ``lambda`` is ``lam`` in Python (a keyword), and reports of a
service before 2026-11 named the measured displacements ``rms_deviation``/``max_deviation``
(both still validate). The model only describes: the engine builds the report as a plain dict
and the API passes it through unvalidated, so a new member never breaks a reader.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Literal

from pydantic import AliasChoices, BaseModel, ConfigDict, Field

__all__ = ["HistoryEntry", "Report", "report_example"]


class HistoryEntry(BaseModel):
    """One lambda tried by the tau search."""

    model_config = ConfigDict(populate_by_name=True)

    lam: float = Field(alias="lambda", description="lambda of eq. (4).", examples=[0.0123])
    phi: float = Field(description="phi(lambda), eq. (15).", examples=[0.4998])


_TILE = {"index": 0, "points": 750, "halo": 420, "hops": 12, "worker": "pid 101", "seconds": 0.5,
         "phi": 1.7, "factorizations": 1}  # fmt: skip


def _examples(schema: dict[str, Any], cls: type[Any]) -> None:
    schema["examples"] = [report_example()]


class Report(BaseModel):
    """Diagnostics of a smoothing run: exactly ``SmoothResult.report()`` of ``service.core``."""

    model_config = ConfigDict(extra="allow", populate_by_name=True, json_schema_extra=_examples)

    #: Members present only in some reports, and when (every other member is in every one).
    PRESENT_ONLY: ClassVar[Mapping[str, str]] = {
        "spectrum": "params.spectrum and an input small enough (SPECTRUM_MAX_POINTS)",
        "tiles": "tiled runs (params.tile_points)",
    }

    lam: float = Field(alias="lambda", description="The lambda used.", examples=[0.0123])
    phi: float = Field(description="phi(lambda) = ||D(X - P)||_F^2 reached.", examples=[0.4998])
    tau: float | None = Field(
        description="Requested smoothing factor (null when lam was given).", examples=[0.5]
    )
    relative_error: float | None = Field(description="|phi - tau| / tau.", examples=[0.0004])
    converged: bool = Field(
        description="Whether the tau search met the tolerance.", examples=[True]
    )
    iterations: int = Field(description="lambda values tried.", examples=[6])
    factorizations: int = Field(description="Numeric factorizations done.", examples=[6])
    solves: int = Field(
        default=0, description="Solves with a factorization (all columns).", examples=[7]
    )
    matvecs: int = Field(default=0, description="Products with L^T L (Lanczos, CG).", examples=[0])
    search: str = Field(
        default="none",
        description="lambda search: auto, newton, rational, none.",
        examples=["auto"],
    )
    order: int = Field(default=1, description="Iterated Tikhonov order k.", examples=[1])
    method: str = Field(
        default="tikhonov", description="tikhonov or windowed-sinc.", examples=["tikhonov"]
    )
    history: list[HistoryEntry] = Field(
        description="(lambda, phi) for every lambda tried.",
        examples=[[{"lambda": 0.01, "phi": 0.41}, {"lambda": 0.0123, "phi": 0.4998}]],
    )
    n_points: int = Field(
        description="Points smoothed (after welding: points_solved).", examples=[2930]
    )
    points_in: int = Field(
        description="Vertices (points) of the input as read, before welding.", examples=[2930]
    )
    points_solved: int = Field(
        description="Points the engine smoothed, after welding coincident vertices.",
        examples=[2930],
    )
    points_out: int = Field(
        description="Vertices of the output (the input's count, less the outliers "
        "outliers='drop' leaves out).",
        examples=[2930],
    )
    welded_pairs: int = Field(
        description="Vertices welded onto a coincident vertex (points_in - points_solved).",
        examples=[0],
    )
    dimension: int = Field(description="Coordinates per point.", examples=[3])
    kind: str = Field(description="mesh, curve or cloud.", examples=["mesh"])
    laplacian: str = Field(description="Laplacian variant used.", examples=["normalized"])
    weights: str = Field(description="Weight scheme used.", examples=["mean-value"])
    n_fixed: int = Field(description="Points held fixed.", examples=[0])
    rms_displacement: float = Field(
        validation_alias=AliasChoices("rms_displacement", "rms_deviation"),
        description="RMS of ||x_i - p_i|| (was ``rms_deviation`` before 2026-11).",
        examples=[0.013],
    )
    max_displacement: float = Field(
        validation_alias=AliasChoices("max_displacement", "max_deviation"),
        description="Maximum of ||x_i - p_i||, a measurement (``params.max_deviation`` is the "
        "bound; was ``max_deviation`` before 2026-11).",
        examples=[0.041],
    )
    volume_scale: float | None = Field(
        description="Scale applied to preserve volume.", examples=[None]
    )
    timings: dict[str, float] = Field(
        description="Seconds per stage.",
        examples=[{"laplacian": 0.004, "analysis": 0.002, "solve": 0.011, "total": 0.03}],
    )
    solver: str = Field(
        description="cholmod, superlu, cg (matrix-free), lanczos (the default's one Lanczos "
        "run: knee, lambda and solution without a factorization) or none (filter).",
        examples=["cholmod"],
    )
    warnings: list[str] = Field(description="Anything the user should know.", examples=[[]])
    warning_details: list[dict[str, Any]] = Field(
        description="The warnings as records, in the same order: code (stable, "
        "service.core.warnings.CODES), message (as in warnings) and the numbers it states.",
        examples=[[]],
    )
    spectrum: dict[str, list[float]] | None = Field(
        default=None,
        description="Singular values and filter factors, when requested.",
        examples=[{"sigma": [3.1, 1.7, 0.4], "gamma": [0.0013, 0.0042, 0.071]}],
    )
    # --- core-quality keys ---
    displacement: str = Field(
        default="free", description="free or normal (along normals only).", examples=["free"]
    )
    tau_rule: str = Field(
        default="tau",
        description="How lambda was set: lam, tau, rms, auto or gcv.",
        examples=["auto"],
    )
    sigma_estimate: float | None = Field(
        default=None,
        description="Estimated noise level across the shape (automatic tau).",
        examples=[0.0099],
    )
    tau_how: str | None = Field(
        default=None,
        description="How the automatic tau was chosen, in words.",
        examples=[
            "automatic: noise found: sigma = 0.0099; tau = 0.0294 (discrepancy principle: "
            "1 x 1 x sigma^2 x sum omega^2 over 300 free points)"
        ],
    )
    bound: dict[str, Any] | None = Field(
        default=None,
        description="max_deviation bound: {max_deviation, rounds, clipped}.",
        examples=[{"max_deviation": 0.02, "rounds": 3, "clipped": 12}],
    )
    noise_found: bool | None = Field(
        default=None,
        description="Automatic tau: whether noise was found (false: the input was returned "
        "unchanged, tau_how says why).",
        examples=[True],
    )
    unchanged: str | None = Field(
        default=None,
        description="Nothing was smoothed (the points are the input's, bit for bit): 'copied' "
        "(the output file is the input's bytes) or 'converted' (a straight conversion to "
        "another format or with writer options); null when smoothed or not written to a file.",
        examples=[None],
    )
    outlier_count: int = Field(
        default=0,
        description="Points the robust data weights treated as outliers (robust).",
        examples=[2],
    )
    outliers: list[int] = Field(
        default_factory=list,
        description="Indices of the points treated as outliers.",
        examples=[[17, 804]],
    )
    outlier_mode: Literal["flag", "drop", "pull"] | None = Field(
        default=None,
        description="What happened to the outliers (params.outliers): 'flag' kept at their "
        "input positions and flagged in the output where the format holds a flag (LAS "
        "classification 7, a PLY/PCD 'outlier' attribute), 'drop' left out of the output, "
        "'pull' pulled back into their neighbours' ring; null when there were none.",
        examples=["flag"],
    )
    data_weights: str | None = Field(
        default=None,
        description="Data weights applied beyond the user's: 'robust (<rule>)', 'noise' "
        "(1/sigma_i, uneven noise) or both; null for none.",
        examples=["robust (huber)"],
    )
    tangential: dict[str, Any] | None = Field(
        default=None,
        description="Meshes, normal displacement with the automatic tau: the step along the "
        "surface (share, budget, psi, steps, reverted); the total deviation is phi + psi.",
        examples=[{"share": 0.4, "budget": 0.012, "psi": 0.0119, "steps": 3, "reverted": 0}],
    )
    output_deviation: dict[str, float] | None = Field(
        default=None,
        description="What the output is: its own deviation total = ||D(X - P)||_F^2 (input "
        "frame, the run's weights), then its parts: tikhonov (phi of the solve at the reported "
        "lambda), tangential (the tangential step's psi) and other (outliers placed without "
        "their data weight, volume rescaling, clipping); null when nothing was solved.",
        examples=[{"total": 3.42, "tikhonov": 1.22, "tangential": 2.2, "other": 0.0}],
    )
    shape_warnings: list[str] = Field(
        default_factory=list,
        description="The shape checks' warnings (also in warnings); strict fails on any.",
        examples=[[]],
    )
    flipped_faces: int | None = Field(
        default=None,
        description="Faces whose normal turned against the input's (meshes).",
        examples=[0],
    )
    folded_faces: int | None = Field(
        default=None,
        description="Faces folded against their neighbours in the result.",
        examples=[0],
    )
    folded_input: int | None = Field(
        default=None,
        description="Faces folded against their neighbours in the input.",
        examples=[0],
    )
    new_folds: int | None = Field(
        default=None,
        description="Folded faces with no folded input face sharing a vertex.",
        examples=[0],
    )
    volume_change: float | None = Field(
        default=None,
        description="Relative change of the enclosed volume (closed meshes) or area (closed "
        "2-D polygons).",
        examples=[-0.0014],
    )
    area_change: float | None = Field(
        default=None,
        description="Relative change of the surface area (meshes) or length.",
        examples=[-0.016],
    )
    moved_far: int | None = Field(
        default=None,
        description="Points that moved more than 5x the RMS deviation.",
        examples=[0],
    )
    # --- tiled runs (issue 23) and the plan (issue 29) ---
    tiles: dict[str, Any] | None = Field(
        default=None,
        description="Tiled runs (tile_points): count, tile_points, halo_hops, hop_length, "
        "rounds and every tile (index, points, halo, hops, worker, seconds, phi, "
        "factorizations); absent for untiled runs.",
        examples=[
            {
                "count": 2,
                "tile_points": 1000,
                "halo_hops": 12,
                "hop_length": 0.08,
                "rounds": 1,
                "tiles": [_TILE, {**_TILE, "index": 1, "worker": "pid 102", "phi": 1.6}],
            }
        ],
    )
    plan: dict[str, Any] | None = Field(
        default=None,
        description="every automatic choice of the run with the evidence for it, decided once "
        "(issue 29)",
        examples=[
            {
                "displacement": {
                    "value": "normal",
                    "why": "the quality benchmark's choice for a mesh",
                    "evidence": {"kind": "mesh", "dim": 3, "normal_directions": 1},
                },
                "solver": {
                    "value": "cholmod",
                    "why": "direct: nothing selected the matrix-free path",
                    "evidence": {},
                },
            }
        ],
    )

    @classmethod
    def wire_names(cls) -> dict[str, str]:
        """Python field name -> JSON member (``lam`` -> ``lambda``), in the model's order."""
        return {name: f.alias or name for name, f in cls.model_fields.items()}


def report_example() -> dict[str, Any]:
    """The example report of the documentation: each member every report has, with its first
    example (the members with a default are shown by their own examples)."""
    return {
        f.alias or name: f.examples[0]
        for name, f in Report.model_fields.items()
        if f.is_required() and f.examples
    }
