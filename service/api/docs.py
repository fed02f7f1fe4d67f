"""OpenAPI fragments shared by the routers (request bodies, problem responses, media types)."""

from __future__ import annotations

from typing import Any

from service.api.problems import PROBLEM_MEDIA_TYPE
from service.api.schemas import Problem, SmoothJsonRequest
from service.io.registry import FORMATS

__all__ = [
    "CRS_QUERY_DESCRIPTION",
    "FORMAT_QUERY_DESCRIPTION",
    "JOB_SUBMIT_OPENAPI",
    "MEDIA_TYPES",
    "PARAMS_EXAMPLE",
    "RESULT_CONTENT",
    "SMOOTH_OPENAPI",
    "document_common_answers",
    "problem_responses",
]

MEDIA_TYPES: dict[str, str] = {name: f.media_type for name, f in FORMATS.items()}

FORMAT_QUERY_DESCRIPTION = f"Output format: {', '.join(FORMATS)} (default: the input's format)."
CRS_QUERY_DESCRIPTION = (
    "Geographic input (GPX, GeoJSON) written to a projected format: the output's projected "
    "CRS, an EPSG code (``32633``, ``EPSG:32633``) or ``utm`` (the WGS84 UTM zone of the data's "
    "centre). Default: metres in the local east/north/up frame about the data's centre, "
    "recorded in the file. 422 (field ``crs``) for other input, a longitude/latitude output or "
    "a CRS that is not projected."
)
#: ``format`` was the query's name before ``output_format`` (every surface now says which file).
FORMAT_ALIAS_DESCRIPTION = "Deprecated: the former name of ``output_format``."


def output_format(output: object | None, alias: object | None) -> str | None:
    """The ``output_format`` query, else its deprecated name ``format`` (422 if they differ)."""
    if output and alias and str(output) != str(alias):
        from service.api.errors import ApiProblem

        raise ApiProblem(
            422,
            f"output_format={output} and format={alias} (its deprecated name) disagree",
            code="invalid-request",
            field="output_format",
        )
    chosen = output or alias
    return str(chosen) if chosen else None


_DESCRIPTIONS: dict[int, str] = {
    400: "Malformed request, file or body (the parser's message in ``detail``), or a ``Host`` "
    "this server does not answer for.",
    401: "No API key, or not a valid one (keys are configured).",
    403: "A state-changing request from another origin's page without an API key.",
    404: "Unknown job (or another key's).",
    408: "The request body stalled (no byte for ``timeout_body_read`` seconds).",
    409: "The job has no result (yet), or the Idempotency-Key was used with another request.",
    413: "Request body above ``max_upload_bytes``, input above the key's point or face bound, "
    "or more work than one request may do (time, memory).",
    415: "Unknown file format or content type.",
    422: "Invalid parameters or geometry (e.g. tau outside (0, phi(0)), a bound of the key "
    "exceeded); ``field`` / ``errors`` name the input at fault.",
    431: "The request header is larger than 16 KiB.",
    429: "Rate limit or quota of the key exceeded; ``Retry-After`` says when to retry.",
    500: "Unexpected error (logged; quote ``request_id``).",
    503: "The job queue or its storage is unavailable, or the server is overloaded "
    "(``Retry-After``).",
    507: "The job store is out of space.",
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


def _spec_answer(status: int) -> dict[str, Any]:
    answer: dict[str, Any] = {
        "description": _DESCRIPTIONS[status],
        "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
    }
    if status in (429, 503, 507):
        answer["headers"] = {
            "Retry-After": {"description": "Seconds to wait.", "schema": {"type": "integer"}}
        }
    return answer


_PROBES = ("/healthz", "/readyz")
_UNSAFE = ("post", "put", "patch", "delete")


def document_common_answers(spec: dict[str, Any], *, keys_possible: bool = True) -> None:
    """Add the answers any operation can give, besides its own, to every operation.

    Every request can be malformed or name a foreign ``Host`` (400), stall its body (408),
    send too large a body (413) or header (431) or hit a bug (500), and come on a connection
    over the per-client or server bound (429, 503: :mod:`service.api.http.protocol`); all but
    the probes can meet an overloaded server (503). ``/v1`` operations need a key when keys are
    configured (401) and are rate limited (429); state-changing ones refuse other origins
    without a key (403); uploads can meet a full disk (507).
    """
    for path, operations in spec.get("paths", {}).items():
        for method, operation in operations.items():
            statuses = [400, 408, 413, 429, 431, 500, 503]
            if path.startswith("/v1/") and keys_possible:
                statuses += [401]
            if method in _UNSAFE:
                statuses.append(403)
            if method == "post" and path.startswith("/v1/"):
                statuses.append(507)
            answers = operation.setdefault("responses", {})
            for status in statuses:
                answers.setdefault(str(status), _spec_answer(status))
            for code in ("429", "503", "507"):  # their own entries too: Retry-After is sent
                if code in answers:
                    answers[code].setdefault("headers", _spec_answer(int(code))["headers"])
            operation["responses"] = dict(sorted(answers.items()))


#: Every media type a result can have (from the formats of the io registry).
def _result_schema(media: str) -> dict[str, Any]:
    if media == "application/json":
        return {"$ref": "#/components/schemas/GeometryJson"}
    if media.endswith("+json"):  # GeoJSON: a JSON document (RFC 7946), not a byte string
        return {"type": "object", "description": "A GeoJSON FeatureCollection (RFC 7946)."}
    return {"type": "string", "format": "binary"}


RESULT_CONTENT: dict[str, Any] = {
    media: {"schema": _result_schema(media)}
    for media in dict.fromkeys(f.media_type.split(";")[0].strip() for f in FORMATS.values())
}


#: Prefilled by Swagger UI's "Try it out": scale-free and mild on any input (lambda is
#: dimensionless for the normalized Laplacian), never a tau that collapses a small model.
PARAMS_EXAMPLE = '{"lam": 1.0}'

_MULTIPART_SCHEMA: dict[str, Any] = {
    "type": "object",
    "required": ["file", "params"],
    "additionalProperties": False,  # any other part is refused (422 unknown form field)
    "properties": {
        "file": {
            "type": "string",
            "format": "binary",
            "description": "The geometry file; its format comes from the input_format part, "
            "the file name's extension, the part's Content-Type or the content.",
        },
        "params": {
            "type": "string",
            "description": "SmoothingParams as a JSON object, sent as a text field or as a JSON "
            "file part. At most one of tau, rms or lam (none: tau from the estimated noise); lam "
            "(no search) is scale-free, tau and rms are in the input's units (docs/method.md, "
            "'Choosing tau'). Must be JSON (anything else is a 422).",
            "contentMediaType": "application/json",
            "contentSchema": {"$ref": "#/components/schemas/SmoothingParams"},
            "example": PARAMS_EXAMPLE,
        },
        "input_format": {
            "type": "string",
            "enum": list(FORMATS),
            "description": "Input format when the file name has no telling extension.",
        },
        "format": {
            "type": "string",
            "enum": list(FORMATS),
            "deprecated": True,
            "description": "Deprecated: the former name of input_format.",
        },
        "webhook_url": {
            "type": "string",
            "format": "uri",
            "description": "Where the finished job is POSTed (signed; public addresses only "
            "unless the server allows private ones).",
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
                    "encoding": {"params": {"contentType": "application/json, text/plain"}},
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
