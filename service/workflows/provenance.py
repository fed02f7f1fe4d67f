"""What smoothed an output, recorded in it (issue 41): a LAS/LAZ output's header says
``geosmooth <version>`` (generating software), ``geosmooth smoothing`` (system identifier) and
the day it was written (``SOURCE_DATE_EPOCH``'s day when set, for reproducible outputs), as
PDAL's ``writers.las`` records itself (:func:`service.io.formats.las_meta.stamp`). An output
that is the input's bytes (nothing smoothed) is not stamped: it stays byte-identical.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

__all__ = ["software_version", "stamp_bytes", "stamp_file"]

_STAMPED = ("las", "laz")


def software_version() -> str:
    """The installed geosmooth version (``unknown`` in an uninstalled source tree)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("geosmooth")
    except PackageNotFoundError:
        return "unknown"


def _today() -> datetime.date:
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    if epoch.isdigit():
        return datetime.datetime.fromtimestamp(int(epoch), datetime.UTC).date()
    return datetime.date.today()


def stamp_bytes(data: bytes, fmt: str) -> bytes:
    """``data`` (a ``fmt`` file) with its header stamped, when ``fmt`` keeps such a record."""
    if fmt not in _STAMPED or len(data) < 94 or data[:4] != b"LASF":
        return data
    from service.io.formats.las_meta import stamp

    out = bytearray(data)
    stamp(out, software_version(), _today())
    return bytes(out)


def stamp_file(path: Path, fmt: str) -> None:
    """Stamp the header of the ``fmt`` file at ``path`` in place (the streamed path's output)."""
    if fmt not in _STAMPED:
        return
    from service.io.formats.las_meta import stamp

    with open(path, "r+b") as fh:
        head = bytearray(fh.read(94))
        if len(head) < 94 or head[:4] != b"LASF":
            return
        stamp(head, software_version(), _today())
        fh.seek(0)
        fh.write(head)
