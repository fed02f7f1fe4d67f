"""The geosmooth JSON schema (:data:`GEOMETRY_JSON_SCHEMA`), shared by files and the HTTP API."""

from __future__ import annotations

from typing import Any

__all__ = ["ATTRIBUTE_TYPES", "GEOMETRY_JSON_SCHEMA"]

_INDEX = {"type": "integer", "minimum": 0}
ATTRIBUTE_TYPES = (
    "bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
    "float32", "float64",
)  # fmt: skip

GEOMETRY_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "geosmooth geometry",
    "description": "Points (n x s, any s >= 1) with optional 0-based connectivity.",
    "type": "object",
    "required": ["points"],
    "additionalProperties": False,
    "properties": {
        "points": {
            "description": "n points, each a list of s >= 1 coordinates (the same s for all).",
            "type": "array",
            "minItems": 1,
            "items": {"type": "array", "minItems": 1, "items": {"type": "number"}},
        },
        "faces": {
            "description": "Faces as 0-based vertex indices; polygons are fan-triangulated.",
            "type": "array",
            "items": {"type": "array", "minItems": 3, "items": _INDEX},
        },
        "edges": {
            "description": "Standalone edges (0-based vertex index pairs).",
            "type": "array",
            "items": {"type": "array", "minItems": 2, "maxItems": 2, "items": _INDEX},
        },
        "polylines": {
            "description": "Open or closed polylines through 0-based vertex indices.",
            "type": "array",
            "items": {
                "type": "object",
                "required": ["indices"],
                "additionalProperties": False,
                "properties": {
                    "indices": {"type": "array", "minItems": 2, "items": _INDEX},
                    "closed": {"type": "boolean", "default": False},
                },
            },
        },
        "weights": {
            "description": "One positive weight per point (omega_i of the report).",
            "type": "array",
            "items": {"type": "number", "exclusiveMinimum": 0},
        },
        "fixed": {
            "description": "0-based indices of points kept exactly in place.",
            "type": "array",
            "items": _INDEX,
        },
        "comments": {
            "description": "Free text carried to written files.",
            "type": "array",
            "items": {"type": "string"},
        },
        "attributes": {
            "description": "Per-point values written back unchanged (colours, intensity, labels,"
            " ...): name -> n numbers, or n lists of k numbers.",
            "type": "object",
            "additionalProperties": {
                "type": "array",
                "items": {
                    "oneOf": [
                        {"type": "number"},
                        {"type": "array", "items": {"type": "number"}},
                    ]
                },
            },
        },
        "attribute_types": {
            "description": "numpy dtype of an attribute (default float64, or int64 for"
            ' integers), e.g. {"red": "uint8"}.',
            "type": "object",
            "additionalProperties": {"type": "string", "enum": list(ATTRIBUTE_TYPES)},
        },
        "normals": {
            "description": "Per-point normals (n x 3); recomputed from the smoothed points on"
            " output unless normals=drop.",
            "type": "array",
            "items": {"type": "array", "minItems": 3, "maxItems": 3, "items": {"type": "number"}},
        },
        "precision": {
            "description": "How the points were stored (float32 or float64): what"
            " precision=input writes.",
            "type": "string",
            "enum": ["float32", "float64"],
        },
    },
}
