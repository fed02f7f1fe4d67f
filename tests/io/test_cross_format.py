"""Every (input kind x output format) pair: round-trips through the output format's reference
readers, or is refused before smoothing with a one-line error naming the formats that can hold it.

The pairs come from the registry (:data:`service.io.FORMATS`), so a new format is covered as
soon as it is registered: it is read back with its reference reader from
:data:`tests.io.cross_readers.READERS` (the library people use for it), or with geosmooth's own
reader when it has none listed there, and with Open3D wherever Open3D reads the format
(:data:`tests.io.cross_readers.OPEN3D`); coordinates are compared, not only counts. A mesh or
polyline written to a format holding points only is checked as its vertices, with a note.
Inputs are small (<= 50 points) and their coordinates have 6 decimals, so text writers (which keep
the input's digits) are exact to 5e-7; float32-only formats are checked to half a float32 step.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from service.io import FORMATS, GeometryDocument, read_geometry, write_geometry
from service.io.dispatch import OutputRefused, check_output, input_kinds, is_geographic
from service.io.holds import dropped_kinds, output_notes
from tests.io.cross_readers import OPEN3D, READERS, Back, _ours

# ----------------------------------------------------------------------------- inputs


def _mesh() -> GeometryDocument:
    n = 5
    xs = np.linspace(0.0, 2.0, n)
    X, Y = np.meshgrid(xs, xs)
    v = np.column_stack([X.ravel(), Y.ravel(), 0.1 * np.sin(3 * X.ravel())])
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            faces += [(a, a + 1, a + n + 1), (a, a + n + 1, a + n)]
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    return read_geometry(text.encode(), "obj")


def _polyline() -> GeometryDocument:
    t = np.linspace(0.0, 3.0, 20)
    v = np.column_stack([t, np.sin(t), 0.1 * t])
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
    text += "l " + " ".join(str(i + 1) for i in range(12)) + "\n"
    text += "l " + " ".join(str(i + 1) for i in range(12, 20)) + "\n"
    return read_geometry(text.encode(), "obj")


def _cloud(offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> GeometryDocument:
    rng = np.random.default_rng(7)
    v = rng.random((40, 3)) * 10 + np.asarray(offset)
    c = rng.integers(0, 256, (40, 3))
    rows = zip(v.tolist(), c.tolist(), strict=True)
    text = "x y z red green blue\n" + "".join(
        f"{a:.6f} {b:.6f} {d:.6f} {r} {g} {bl}\n" for (a, b, d), (r, g, bl) in rows
    )
    return read_geometry(text.encode(), "xyz")


def _track() -> GeometryDocument:
    rng = np.random.default_rng(3)
    segs = []
    for s in range(2):
        pts = "".join(
            f'<trkpt lat="{45.38 + 1e-4 * i + 1e-6 * rng.random():.7f}" '
            f'lon="{14.14 + 2e-4 * i + s * 1e-3:.7f}"><ele>{700 + i * 0.5:.1f}</ele></trkpt>'
            for i in range(10)
        )
        segs.append(f"<trkseg>{pts}</trkseg>")
    text = (
        '<?xml version="1.0" encoding="UTF-8"?><gpx version="1.1" creator="test" '
        f'xmlns="http://www.topografix.com/GPX/1/1"><trk>{"".join(segs)}</trk></gpx>'
    )
    return read_geometry(text.encode(), "gpx")


INPUTS: dict[str, Callable[[], GeometryDocument]] = {
    "mesh": _mesh,
    "polyline": _polyline,
    "cloud": _cloud,
    "georeferenced-cloud": lambda: _cloud((665000.0, 5648000.0, 240.0)),
    "gpx-track": _track,
}

WRITABLE = [name for name, f in FORMATS.items() if f.write is not None]


# ----------------------------------------------------------------------------- checks


def _moved(doc: GeometryDocument) -> NDArray[np.float64]:
    pts = doc.geometry.points
    extent = float(np.max(np.ptp(pts, axis=0)))
    rng = np.random.default_rng(11)
    return pts + rng.normal(0.0, 1e-3 * extent, pts.shape)


def _tolerance(fmt: str, expected: NDArray[np.float64], back: Back) -> float:
    spec = FORMATS[fmt]
    if spec.coordinates == "float64":  # inputs have 6 decimals: text writers keep them,
        return max(5.1e-7, 1.01 * back.resolution)  # binary ones are exact (LAS: its scale)
    centre = (expected.min(axis=0) + expected.max(axis=0)) / 2
    stored = expected - centre if spec.coordinates == "float32-offset" else expected
    step = float(np.spacing(np.float32(np.max(np.abs(stored)))))
    return max(step * 1.01 + 1e-12, 1.01 * back.resolution)


def _corners(points: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Face corner positions, each face rotated to start at its smallest corner (sorted rows)."""
    tri = points[faces]
    keys = np.lexsort(tri.reshape(len(tri), -1).T[::-1])
    return tri[keys]


def _edge_set(lines: list[list[int]]) -> set[tuple[int, int]]:
    return {(min(a, b), max(a, b)) for ln in lines for a, b in itertools.pairwise(ln)}


def _expected(doc: GeometryDocument, moved: NDArray[np.float64], lonlat: bool) -> Any:
    if not lonlat:
        return moved
    lon, lat, ele = doc.layout.frame.back(moved)  # type: ignore[attr-defined]
    return np.column_stack([lon, lat, ele])


def _check_round_trip(doc: GeometryDocument, fmt: str, back: Back, moved: NDArray[Any]) -> None:
    kinds = input_kinds(doc)
    expected = _expected(doc, moved, back.lonlat)
    if back.lonlat:  # GPX / GeoJSON: the input's 7 decimals of degrees, 1 of elevation
        assert back.points.shape == expected.shape
        np.testing.assert_allclose(back.points[:, :2], expected[:, :2], rtol=0, atol=5.1e-8)
        np.testing.assert_allclose(back.points[:, 2], expected[:, 2], rtol=0, atol=0.051)
        assert [len(ln) for ln in back.lines] == [len(p) for p in doc.polylines]
        return
    tol = _tolerance(fmt, expected, back)
    if dropped_kinds(doc, FORMATS[fmt]):  # the vertices as points, in file order
        assert back.points.shape == expected.shape, fmt
        np.testing.assert_allclose(back.points, expected, rtol=0, atol=tol, err_msg=fmt)
        return
    if "mesh" in kinds:
        assert back.faces is not None and len(back.faces) == len(doc.geometry.faces), fmt
        got = _corners(back.points, back.faces)
        want = _corners(expected, np.asarray(doc.geometry.faces))
        np.testing.assert_allclose(got, want, rtol=0, atol=tol, err_msg=fmt)
        return
    assert back.points.shape == expected.shape, fmt
    np.testing.assert_allclose(back.points, expected, rtol=0, atol=tol, err_msg=fmt)
    if "polyline" in kinds and back.reads_lines:  # the same edges (PLY: an edge element)
        assert _edge_set(back.lines) == _edge_set([p.indices.tolist() for p in doc.polylines]), fmt
    if "red" in doc.attributes and FORMATS[fmt].keeps("red") and back.reads_colours:
        colours = np.column_stack([doc.attributes[c] for c in ("red", "green", "blue")])
        assert back.colours is not None, f"{fmt} lost the colours"
        got = back.colours * (255.0 if back.colours.max() <= 1.0 else 1.0)  # OBJ: fractions
        np.testing.assert_allclose(got, colours.astype(np.float64), rtol=0, atol=1e-3)


@pytest.mark.parametrize("fmt", WRITABLE)
@pytest.mark.parametrize("kind", list(INPUTS))
def test_pair_round_trips_or_is_refused(kind: str, fmt: str) -> None:
    doc = INPUTS[kind]()
    moved = _moved(doc)
    try:
        check_output(doc, fmt)
    except OutputRefused as exc:
        text = str(exc)
        assert "\n" not in text and exc.field == "format" and exc.status == 422
        assert text.startswith(f"cannot write {fmt}:") and "instead" in text
        named = text.rsplit("write ", 1)[1].removesuffix(" instead").split(", ")
        assert named and fmt not in named and set(named) <= set(FORMATS)
        for other in named:  # every format named can hold it
            check_output(doc, other)
        spec = FORMATS[fmt]
        held = input_kinds(doc) <= spec.kinds or "cloud" in spec.kinds
        assert not held or (spec.geographic_only and not is_geographic(doc)), (
            f"{fmt} refused {kind} for no registered reason: {text}"
        )
        with pytest.raises(OutputRefused):  # every write checks too
            write_geometry(doc, fmt, moved)
        return
    data = write_geometry(doc, fmt, moved)
    back = READERS.get(fmt, _ours(fmt))(data)
    _check_round_trip(doc, fmt, back, moved)
    if dropped_kinds(doc, FORMATS[fmt]):
        assert any("as points" in n for n in output_notes(doc, fmt)), fmt


def _open3d_reader(doc: GeometryDocument, fmt: str) -> Callable[[bytes], Back] | None:
    readers = OPEN3D.get(fmt, {})
    whole = "mesh" in input_kinds(doc) and not dropped_kinds(doc, FORMATS[fmt])
    return readers.get("mesh") if whole else readers.get("points")


#: Where Open3D's coordinates are float32, not the file's: its OBJ reader (tinyobjloader)
#: parses floats; its glTF reader adds the node translation in float32.
_OPEN3D_FLOAT32 = {"obj", "glb"}


@pytest.mark.parametrize("fmt", sorted(OPEN3D))
@pytest.mark.parametrize("kind", list(INPUTS))
def test_open3d_reads_every_output_it_opens(kind: str, fmt: str) -> None:
    """Open3D 0.20 reads each output of a format it opens with the coordinates written."""
    pytest.importorskip("open3d")
    doc = INPUTS[kind]()
    reader = _open3d_reader(doc, fmt)
    try:
        check_output(doc, fmt)
    except OutputRefused:
        return
    if reader is None:  # e.g. a polyline OBJ: Open3D reads OBJ meshes only
        return
    moved = _moved(doc)
    back = reader(write_geometry(doc, fmt, moved))
    if fmt in _OPEN3D_FLOAT32:
        back.resolution = float(np.spacing(np.float32(np.max(np.abs(moved)))))  # 2 roundings
    _check_round_trip(doc, fmt, back, moved)


def test_every_writable_format_has_a_reader() -> None:
    """A new format round-trips at least through geosmooth's own reader."""
    for fmt in WRITABLE:
        assert fmt in READERS or FORMATS[fmt].read is not None


def test_output_notes_stay_true() -> None:
    """Notes about kept columns only where true; geographic input written planar says so."""
    from service.io.dispatch import output_notes

    cloud = _cloud()
    assert any(n.startswith("kept 3 extra columns") for n in output_notes(cloud, "ply"))
    notes = output_notes(cloud, "off")
    assert not any(n.startswith("kept") for n in notes)
    assert "OFF keeps no red, green, blue: not written" in notes
    track = _track()
    assert not any("not longitude/latitude" in n for n in output_notes(track, "geojson"))
    assert any("not longitude/latitude" in n for n in output_notes(track, "ply"))
