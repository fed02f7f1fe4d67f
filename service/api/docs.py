"""OpenAPI fragments shared by the routers (request bodies, problem responses, media types)."""

from __future__ import annotations

from typing import Any

from service.api.problems import PROBLEM_MEDIA_TYPE
from service.api.schemas import Problem, SmoothJsonRequest
from service.io.registry import FORMATS

__all__ = [
    "FORMAT_QUERY_DESCRIPTION",
    "JOB_SUBMIT_OPENAPI",
    "MEDIA_TYPES",
    "RESULT_CONTENT",
    "SMOOTH_OPENAPI",
    "problem_responses",
]

MEDIA_TYPES: dict[str, str] = {name: f.media_type for name, f in FORMATS.items()}

FORMAT_QUERY_DESCRIPTION = (
    f"Output format: {', '.join(FORMATS)} (default: the input's format)."
)

_DESCRIPTIONS: dict[int, str] = {
    400: "Malformed file or body (the parser's message in ``detail``).",
    404: "Unknown job.",
    409: "The job has no result (yet).",
    413: "Request body larger than ``max_upload_bytes`` or input above the point limit.",
    415: "Unknown file format or content type.",
    422: "Invalid parameters or geometry; ``field`` / ``errors`` name the input at fault.",
    503: "The job queue is not running.",
}


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries documenting problem details for ``statuses``."""
    return {
        status: {
            "description": _DESCRIPTIONS[status],
            "model": Problem,
            "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
        }
        for status in statuses
    }


RESULT_CONTENT: dict[str, Any] = {
    "application/octet-stream": {
        "schema": {"type": "string", "format": "binary"},
        "example": "ply\nformat ascii 1.0\nelement vertex 3\n...",
    },
    "model/obj": {"schema": {"type": "string"}, "example": "v 0 0 0\nv 1 0 0.05\n..."},
    "text/plain": {"schema": {"type": "string"}, "example": "0 0 0\n1 0 0.05\n"},
    "application/json": {
        "schema": {"type": "object"},
        "example": {"points": [[0, 0, 0], [1, 0, 0.05]]},
    },
}

_MULTIPART_SCHEMA: dict[str, Any] = {
    "type": "object",
    "required": ["file", "params"],
    "properties": {
        "file": {
            "type": "string",
            "format": "binary",
            "description": "The geometry: a PLY, OBJ, XYZ or JSON file.",
        },
        "params": {
            "type": "string",
            "description": 'SmoothingParams as a JSON object, e.g. {"tau": 0.5}.',
            "example": '{"tau": 0.5}',
        },
        "format": {
            "type": "string",
            "enum": list(FORMATS),
            "description": "Input format when the file name has no telling extension.",
        },
        "weld": {
            "type": "boolean",
            "default": False,
            "description": "Weld exactly coincident vertices before smoothing (meshes stored "
            "with split normals); the result keeps the input's vertex count and order.",
        },
    },
}


def _request_body(description: str) -> dict[str, Any]:
    return {
        "requestBody": {
            "required": True,
            "description": description,
            "content": {
                "multipart/form-data": {
                    "schema": _MULTIPART_SCHEMA,
                    "encoding": {"params": {"contentType": "application/json"}},
                },
                "application/json": {
                    "schema": {"$ref": "#/components/schemas/SmoothJsonRequest"},
                    "example": SmoothJsonRequest.model_config["json_schema_extra"]["examples"][0],  # type: ignore[index]
                },
            },
        }
    }


JOB_SUBMIT_OPENAPI = _request_body(
    "An uploaded file with parameters, or the geometry inline as JSON."
)
SMOOTH_OPENAPI = _request_body(
    "An uploaded file with parameters, or the geometry inline as JSON"
    " (at most ``sync_max_points`` points, default 20000)."
)
