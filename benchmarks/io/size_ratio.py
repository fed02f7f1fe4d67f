"""Output/input size of every shared file, written back in its own format.

``moved``: every point displaced by a random vector of 1e-4 of the extent in the coordinates
that vary (as smoothing does: all digits change; a plane stays a plane); ``same``: the points
as read. Run from the repository root::

    PYTHONPATH=. python benchmarks/io/size_ratio.py [DATA_DIR]

Prints a markdown table (kept in ``service/io/README.md``); ``tests/io`` checks the same bound.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from service.io import read_geometry, write_geometry

SUFFIXES = {".ply", ".obj", ".xyz", ".gpx", ".geojson", ".dxf", ".stl", ".off", ".pcd", ".las"}


def moved_points(doc):  # type: ignore[no-untyped-def]
    """The document's points displaced by 1e-4 of the extent (seeded)."""
    pts = doc.geometry.points
    extent = float(np.max(np.ptp(pts, axis=0))) or 1.0
    varies = np.ptp(pts, axis=0) > 0  # a plane stays a plane (z = 0 of a map stays 0)
    return pts + np.random.default_rng(0).normal(size=pts.shape) * 1e-4 * extent * varies


def ratios(path: Path) -> tuple[float, float]:
    """(same, moved) output/input size ratios for one file."""
    raw = path.read_bytes()
    doc = read_geometry(raw, filename=path.name)
    same = len(write_geometry(doc, doc.source_format)) / len(raw)
    moved = len(write_geometry(doc, doc.source_format, moved_points(doc))) / len(raw)
    return same, moved


def main() -> None:
    data = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parents[3] / "shared" / "data"
    print("| file | size | same | moved |")
    print("|---|---:|---:|---:|")
    for path in sorted(p for p in data.iterdir() if p.suffix in SUFFIXES):
        same, moved = ratios(path)
        print(f"| {path.name} | {path.stat().st_size} | {same:.3f} | {moved:.3f} |")


if __name__ == "__main__":
    main()
