"""PCD written from another format: a layout that PCL, Open3D and pypcd4 all read back exactly.

Open3D's PCD reader (0.20, ``FilePCD.cpp``) decodes binary fields of ``TYPE F`` only with
``SIZE 4``: a binary ``F 8`` coordinate reads as 0 (the issue-32 bug: XYZ -> PCD opened as all
zeros). Its ASCII reader parses every ``F`` value with ``strtod`` whatever the ``SIZE``, so ASCII
doubles read back bit-exact. Hence:

* **float32 keeps the data** (float32 input; text input whose decimals float32 reproduces: half a
  float32 step at the largest coordinate is at most a quarter of the input's last decimal, e.g.
  the 6-decimal mug scene within 2.5 m; double input whose values are all float32): ``DATA
  binary``, ``x y z`` as ``F 4``, colours packed in ``rgb`` ``F 4`` (``rgba`` ``U 4`` with alpha).
* **doubles needed** (georeferenced text such as 665187.522077, binary doubles):
  ``DATA ascii``, ``x y z`` as ``F 8`` with the input's digits (shortest round-trip text for
  binary doubles), colours as PCL's own ASCII writer stores them: ``rgb`` ``U 4``, the integer
  ``0x00RRGGBB`` (PCL writes ``rgb`` as ``U`` in ASCII headers because packed floats can be NaN).

``precision="float32"`` forces the first layout, ``"float64"`` the second. Measured in
``tests/io/test_cross_format.py``: Open3D, pypcd4 and geosmooth read the coordinates within the
input's resolution and the colours exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io._shared.coords import as_xyz
from service.io._shared.plain import PlainDocument

__all__ = ["fresh_pcd"]

_NORMALS = ("normal_x", "normal_y", "normal_z")
_RGB = ("red", "green", "blue")
_KINDS = {"f": "F", "u": "U", "i": "I"}


def _channel(values: NDArray[Any]) -> NDArray[np.uint32]:
    """One colour channel as 8-bit values (16-bit scaled by 255/65535, [0, 1] floats by 255)."""
    v = np.asarray(values, dtype=np.float64)
    top = float(np.max(v)) if v.size else 0.0
    if top > 255:
        v = v * (255.0 / 65535.0)
    elif v.dtype.kind == "f" and np.asarray(values).dtype.kind == "f" and top <= 1.0:
        v = v * 255.0
    return np.clip(np.rint(v), 0, 255).astype(np.uint32)


def _packed(attrs: dict[str, NDArray[Any]], ascii_: bool) -> tuple[str, NDArray[Any]] | None:
    """PCL's packed colour field (``rgb`` float32 bits, or ``rgba`` uint32), if coloured."""
    if not all(c in attrs and attrs[c].ndim == 1 for c in _RGB):
        return None
    r, g, b = (_channel(attrs[c]) for c in _RGB)
    word = (r << 16) | (g << 8) | b
    if "alpha" in attrs and attrs["alpha"].ndim == 1:
        return "rgba", word | (_channel(attrs["alpha"]) << 24)
    return "rgb", word if ascii_ else word.view(np.float32)


def float32_keeps(plain: PlainDocument) -> bool:
    """Whether float32 coordinates keep everything the input had (see the module docstring)."""
    mode = plain.options.precision
    if mode != "input":
        return mode == "float32"
    if plain.coordinate_dtype() == np.float32:
        return True
    pts = plain.points
    if not pts.size:
        return True
    text = plain.source.precision.text
    if text and all(s.startswith("%.") and s.endswith("f") for s in text):
        step = min(10.0 ** -int(s[2:-1]) for s in text)
        half = float(np.spacing(np.float32(np.max(np.abs(pts))))) / 2
        return half <= step / 4
    return bool(np.all(pts.astype(np.float32).astype(np.float64) == pts))


def fresh_pcd(plain: PlainDocument) -> tuple[NDArray[Any], list[str], str, dict[str, str]]:
    """Records, header lines, encoding and ASCII specs of a PCD written from another format."""
    pts = as_xyz(plain.points, "pcd")
    binary = float32_keeps(plain)
    cdt = np.dtype(np.float32) if binary else np.dtype(np.float64)
    fields: list[Any] = [(c, cdt) for c in ("x", "y", "z")]
    if plain.normals is not None:
        fields += [(c, np.float32) for c in _NORMALS]
    attrs = {k: v for k, v in plain.attributes.items() if v.dtype.kind in "iuf" and v.ndim <= 2}
    colour = _packed(attrs, ascii_=not binary)
    if colour is not None:
        attrs = {k: v for k, v in attrs.items() if k not in (*_RGB, "alpha")}
        attrs = {colour[0]: colour[1], **attrs}
    fields += [(k, v.dtype, v.shape[1:]) if v.ndim == 2 else (k, v.dtype) for k, v in attrs.items()]
    rec = np.empty(plain.n, dtype=fields)
    for j, c in enumerate(("x", "y", "z")):
        rec[c] = pts[:, j]
    if plain.normals is not None:
        for j, c in enumerate(_NORMALS):
            rec[c] = np.asarray(plain.normals[:, j])
    for k, v in attrs.items():
        rec[k] = v
    specs: dict[str, str] = {}
    if not binary:
        coord = plain.coordinate_specs() if plain.options.precision == "input" else ()
        for j, c in enumerate(("x", "y", "z")):
            specs[c] = coord[j] if j < len(coord) else "%r"
        for k in attrs:
            if k in plain.attributes:
                specs[k] = plain.attribute_spec(k)
    return rec, _header(rec, plain.n, binary), "binary" if binary else "ascii", specs


def _header(rec: NDArray[Any], n: int, binary: bool) -> list[str]:
    names = rec.dtype.names or ()
    return [
        "# .PCD v0.7 - Point Cloud Data file format (written by geosmooth)",
        "VERSION 0.7",
        "FIELDS " + " ".join(names),
        "SIZE " + " ".join(str(rec.dtype[nm].base.itemsize) for nm in names),
        "TYPE " + " ".join(_KINDS[rec.dtype[nm].base.kind] for nm in names),
        "COUNT " + " ".join(str(int(np.prod(rec.dtype[nm].shape or (1,)))) for nm in names),
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA binary" if binary else "DATA ascii",
    ]
