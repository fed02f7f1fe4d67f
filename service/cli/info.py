"""``geosmooth info INPUT``: what an input is and which smoothing budgets make sense.

Prints :func:`service.core.info.describe` as JSON (the body ``POST /v1/info`` returns): size,
kind, bounding box, mean spacing, ``phi(0)`` and the valid ranges of ``tau`` and ``rms``, the
estimated noise level and the budget the automatic rule would choose. Nothing is smoothed.
"""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING, Any, TextIO

from service.cli.errors import CliError
from service.cli.output import check_format
from service.cli.params import params_from_args
from service.cli.smooth import read_input, read_limits
from service.exit_codes import EXIT_OK, EXIT_USAGE

if TYPE_CHECKING:
    from service.io import GeometryDocument

__all__ = ["file_facts", "run"]


def file_facts(doc: GeometryDocument) -> dict[str, Any]:
    """What the file declares, as ``pdal info --summary`` shows it (issue 41): for LAS/LAZ the
    version, point format, dimensions and their types, scales, offsets, bounds in the file's
    units, CRS, class counts and the header's software, system and date
    (:func:`service.io.formats.las_meta.summary`); for other formats the attributes (dimensions)
    and the CRS of geographic input."""
    header = getattr(doc.layout, "header", None)
    pts = doc.geometry.points
    if header is not None and hasattr(header, "parse_crs"):
        from service.io.formats.las_meta import summary

        return summary(header, pts, doc.attributes)
    out: dict[str, Any] = {
        "dimensions": [{"name": n, "type": str(v.dtype)} for n, v in doc.attributes.items()],
        "crs": None,
    }
    if getattr(getattr(doc.layout, "frame", None), "frame", None) is not None:
        out["crs"] = {"epsg": 4326, "name": "WGS 84", "unit": "degree", "projected": False}
    classes = doc.attributes.get("classification")
    if classes is not None:
        import numpy as np

        codes, counts = np.unique(classes, return_counts=True)
        out["classes"] = {str(int(c)): int(k) for c, k in zip(codes, counts, strict=True)}
    return out


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run ``geosmooth info``; prints one JSON object on stdout."""
    import sys

    from service.core.info import describe

    params = params_from_args(ns)
    check_format(ns.input_format, "--input-format")
    if ns.xyz_dims is not None and ns.xyz_dims < 1:
        raise CliError(f"--xyz-dims: must be at least 1, got {ns.xyz_dims}", EXIT_USAGE)
    with read_limits(ns):
        doc = read_input(ns.input, ns.input_format, ns.weld, ns.xyz_dims)
    facts = {"input": ns.input, "input_format": doc.source_format, "format": doc.source_format}
    facts.update(describe(doc.geometry, params))
    facts["file"] = file_facts(doc)
    if doc.weld is not None:
        facts["welded_from"] = int(doc.weld.n_original)
        facts["duplicates_welded"] = int(doc.weld.n_original - doc.geometry.n)  # issue 31
    json.dump(facts, sys.stdout, indent=None if ns.compact else 2, allow_nan=False)
    sys.stdout.write("\n")
    return EXIT_OK
