"""``POST /v1/info``: what an input is and which smoothing factors it admits, without smoothing.

Takes the same request as ``POST /v1/smooth`` (multipart ``file`` [+ ``params``, ``format``,
``weld``] or JSON ``{geometry, params?, weld?}``); ``params`` is optional here (neighbourhood,
weights and fixed points change ``phi(0)``; ``tau``/``rms``/``lam`` are ignored). Answers
:func:`service.core.info.describe` plus what the reader saw (format, polylines, notes).

``GET /v1/limits`` answers the bounds that apply to the caller's key (the web page states them
from there, so the page and the API take the same inputs).

``?preview=true`` adds the geometry for display (the web page's 3-D viewer): positions as
little-endian float32 relative to ``origin`` (the bounding-box centre, so that large coordinates
keep their precision), faces and line segments as uint32, each base64-encoded, all in the
file's vertex order (the order of a job's result).
"""

from __future__ import annotations

import copy
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from pydantic import BaseModel, ConfigDict, Field

from service.api.deps import IntakeDep, PrincipalDep, SettingsDep
from service.api.docs import JOB_SUBMIT_OPENAPI, problem_responses
from service.api.intake.ingest import describe_input
from service.api.schemas import GEOMETRY_EXAMPLE

__all__ = ["Info", "LimitsAnswer", "Preview", "router"]

router = APIRouter(prefix="/v1", tags=["smooth"])


class Preview(BaseModel):
    """The geometry for display, in the file's vertex order."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "origin": [0.5, 0.5, 0.0],
                    "n_points": 3,
                    "dimension": 3,
                    "positions": "AAAAvwAAAL8AAAAAAAAAPwAAAL8AAAAAAAAAvwAAAD8AAAAA",
                    "faces": "AAAAAAEAAAACAAAA",
                    "segments": None,
                }
            ]
        }
    )

    origin: list[float] = Field(description="Added to ``positions`` to get the coordinates.")
    n_points: int = Field(description="Vertices (the file's count, also when welded).")
    dimension: int = Field(description="Coordinates per point in the file.")
    positions: str = Field(
        description="base64 of float32 little-endian (n_points, 3): the first three coordinates "
        "minus origin (2-D data get z = 0)."
    )
    faces: str | None = Field(default=None, description="base64 of uint32 (n_faces, 3).")
    segments: str | None = Field(
        default=None, description="base64 of uint32 (n_segments, 2): polyline and other edges."
    )


class Info(BaseModel):
    """``describe()`` of the input plus what the reader saw."""

    model_config = ConfigDict(
        extra="allow",
        json_schema_extra={
            "examples": [
                {
                    "n_points": 642,
                    "dimension": 3,
                    "kind": "mesh",
                    "n_faces": 1280,
                    "n_edges": 1920,
                    "bbox": {"min": [-1.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0]},
                    "mean_spacing": 0.095,
                    "phi0": 641.6,
                    "tau_range": [0.0, 641.6],
                    "rms_range": [0.0, 1.0],
                    "sigma_estimate": 0.0098,
                    "suggested_tau": 0.062,
                    "suggested_rms": 0.0098,
                    "input_format": "ply",
                    "format": "ply",
                    "filename": "noisy-sphere.ply",
                    "n_polylines": 0,
                    "notes": [],
                    "weld": False,
                }
            ]
        },
    )

    n_points: int = Field(description="Points the engine smooths (after welding).")
    dimension: int = Field(description="Coordinates per point.")
    kind: str = Field(description="mesh, curve or cloud.")
    n_faces: int = Field(description="Triangles.")
    n_edges: int | None = Field(
        description="Neighbour pairs (mesh, curve or neighbourhood edges); null for large "
        "clouds, whose neighbourhoods the job builds."
    )
    bbox: dict[str, list[float]] = Field(description="Bounding box ``{min, max}``.")
    mean_spacing: float = Field(description="Mean edge length or nearest-neighbour distance.")
    phi0: float = Field(description="phi(0) of eq. (14): the largest meaningful tau.")
    phi0_exact: bool = Field(
        default=True,
        description="False for point clouds above the exact-analysis size (setting "
        "``submit_exact_tau_points``): ``phi0`` is then the closed-form upper bound "
        "sum w_i^2 |p_i - p_w|^2 that ``POST /v1/jobs`` checks too, and the noise estimate and "
        "suggestions are left to the job (its automatic tau), as their cost is the job's.",
    )
    tau_range: list[float] = Field(description="Valid tau: the open interval (0, phi(0)).")
    rms_range: list[float] = Field(description="Valid rms: the open interval it maps to.")
    sigma_estimate: float | None = Field(description="Estimated noise level, when available.")
    noise: str | None = Field(
        default=None,
        description="Whether noise was found and the evidence (\"no noise found: ...\" when the "
        "default would return the input unchanged).",
    )
    suggested_tau: float | None = Field(description="A suggested tau, when available.")
    suggested_rms: float | None = Field(description="A suggested rms, when available.")
    input_format: str = Field(description="Format the input was read as.")
    format: str = Field(
        description="Deprecated: the former name of ``input_format``.", deprecated=True
    )
    filename: str | None = Field(default=None, description="Uploaded file name.")
    n_polylines: int = Field(description="Polylines in the file.")
    notes: list[str] = Field(description="What the reader repaired or ignored.")
    weld: bool = Field(description="Whether coincident vertices were welded.")
    preview: Preview | None = Field(default=None, description="With ``?preview=true``.")


def _info_openapi() -> dict[str, Any]:
    """The request body of ``POST /v1/jobs``, with ``params`` optional."""
    spec = copy.deepcopy(JOB_SUBMIT_OPENAPI)
    body = spec["requestBody"]
    body["description"] = "An uploaded file (``params`` optional), or the geometry inline as JSON."
    content = body["content"]
    multipart = content["multipart/form-data"]["schema"]
    multipart["required"] = [name for name in multipart.get("required", []) if name != "params"]
    content["application/json"] = {
        "schema": {
            "type": "object",
            "required": ["geometry"],
            "additionalProperties": False,
            "properties": {
                "geometry": {"$ref": "#/components/schemas/GeometryJson"},
                "params": {"$ref": "#/components/schemas/SmoothingParams"},
                "weld": {"type": "boolean", "default": False},
            },
        },
        "example": {"geometry": GEOMETRY_EXAMPLE},
    }
    return spec


@router.post(
    "/info",
    response_model=Info,
    response_model_exclude_none=False,
    response_description="What was read and the valid smoothing factors.",
    summary="Describe an input (valid tau / rms range) without smoothing it",
    description=(
        "Same request as ``POST /v1/smooth`` (``params`` optional: only neighbourhood, weights "
        "and fixed-point settings matter). Answers the number of points, dimension, kind "
        "(mesh, curve, cloud), faces, edges, polylines, bounding box, mean spacing, "
        "``phi0`` = phi(0) of eq. (14) and the valid ranges of ``tau`` and ``rms`` it implies, "
        "the noise estimate and suggested values when available, and the reader's notes. "
        "``preview=true`` adds the geometry as base64 arrays for display."
    ),
    openapi_extra=_info_openapi(),
    responses=problem_responses(400, 413, 415, 422),
)
async def info(
    request: Request,
    principal: PrincipalDep,
    intake: IntakeDep,
    preview: Annotated[
        bool, Query(description="Include the geometry for display (base64 arrays).")
    ] = False,
) -> dict[str, Any]:
    # parsed and described in a worker process, like every upload (see service.api.intake.request)
    upload = await intake.receive(request)
    try:
        answer = await intake.run(
            request,
            upload,
            principal,
            describe_input,
            params_required=False,
            options={"preview": preview},
        )
    finally:
        upload.discard()
    return answer or {}


class LimitsAnswer(BaseModel):
    """The bounds of the caller's key: what ``POST /v1/jobs``, ``/v1/smooth`` and ``/v1/info``
    accept (``/v1/info`` takes every input ``/v1/jobs`` takes)."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "max_upload_bytes": 268435456,
                    "max_points": 2000000,
                    "max_faces": 4000000,
                    "sync_max_points": 20000,
                    "max_k": 64,
                    "max_iterations": 200,
                    "max_spectrum_points": 3000,
                    "max_active_jobs": 100,
                    "exact_analysis_points": 50000,
                }
            ]
        }
    )

    max_upload_bytes: int = Field(description="Largest request body (413 above).")
    max_points: int = Field(description="Largest input of POST /v1/jobs and /v1/info (points).")
    max_faces: int = Field(description="Largest input of POST /v1/jobs (faces).")
    sync_max_points: int = Field(description="Largest input of POST /v1/smooth (points).")
    max_k: int = Field(description="Largest params.k.")
    max_iterations: int = Field(description="Largest params.max_iterations.")
    max_spectrum_points: int = Field(description="Largest input with params.spectrum.")
    max_active_jobs: int = Field(description="Queued plus running jobs of the key.")
    exact_analysis_points: int = Field(
        description="Largest point cloud whose phi(0) is computed exactly at submit and by "
        "POST /v1/info (larger ones: the closed-form bound, phi0_exact false)."
    )


@router.get(
    "/limits",
    response_model=LimitsAnswer,
    summary="The bounds that apply to this key",
    description=(
        "The sizes and parameter bounds of the caller's key (a keys file can set them per key; "
        "otherwise the ``GEOSMOOTH_*`` settings of the same names). The web page states them."
    ),
    responses=problem_responses(401, 403),
)
async def limits(principal: PrincipalDep, settings: SettingsDep) -> dict[str, Any]:
    bounds = principal.limits
    names = [name for name in LimitsAnswer.model_fields if hasattr(bounds, name)]
    answer: dict[str, Any] = {name: getattr(bounds, name) for name in names}
    answer["exact_analysis_points"] = settings.submit_exact_tau_points
    return answer
