"""geosmooth as a PDAL ``filters.python`` stage (docs/cli.md, "Pipelines as data").

PDAL calls ``smooth(ins, outs)`` with the point view's dimensions as NumPy arrays (``X``, ``Y``,
``Z``, ``Classification``, ...) and the stage's ``pdalargs`` as the module global ``pdalargs``:
geosmooth's parameters (``rms``, ``tau``, ``laplacian``, ...; the ``params`` of a ``--report``
work as they are) and optionally ``where`` (the ``--where`` grammar): points outside it are held
fixed, bit-identical. The stage::

    {"type": "filters.python", "module": "anything", "function": "smooth",
     "script": "docs/recipes/pdal_geosmooth.py",
     "pdalargs": {"rms": 0.02, "where": "Classification == 2"}}

Coordinates come back as doubles; PDAL's writers.las scales them with the file's scale
(``forward=all`` keeps scale, offset and the other dimensions, as ``geosmooth smooth`` does).
"""

from __future__ import annotations

from typing import Any

import numpy as np

pdalargs: dict[str, Any] = {}  # PDAL sets it from the stage's "pdalargs"


def smooth(ins: dict[str, np.ndarray], outs: dict[str, np.ndarray]) -> bool:
    """Smooth ``X, Y, Z`` of ``ins`` into ``outs`` (PDAL's filters.python signature)."""
    import geosmooth
    from service.workflows.selection import fixed_outside

    args = {k: v for k, v in dict(pdalargs).items() if v is not None}
    where = args.pop("where", None)
    fix_classes = args.pop("fix_classes", None)
    for option in ("crs",):  # a --report's pipeline option PDAL does with its own stages
        args.pop(option, None)
    xyz = np.column_stack([ins["X"], ins["Y"], ins["Z"]]).astype(np.float64)
    attrs = {k: v for k, v in ins.items() if k not in ("X", "Y", "Z")}
    fixed = fixed_outside(xyz, attrs, where, fix_classes)
    geometry = geosmooth.Geometry(xyz, fixed=fixed if len(fixed) else None)
    out = geosmooth.smooth(geometry, args).points
    outs["X"], outs["Y"], outs["Z"] = out[:, 0].copy(), out[:, 1].copy(), out[:, 2].copy()
    return True
