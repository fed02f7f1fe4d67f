"""Numbers as text: the input's digits, measured on read and reproduced on write.

A text file's columns are written back with the digits the input used, so an unchanged value
reads back bit-identical and a smoothed one has the input's resolution (the output is as large
as the input). :class:`Digits` measures every token of every column, vectorised over blocks:

* all tokens fixed-point with the same number of decimals ``d`` (``2.025800``): ``"%.{d}f"``;
* otherwise at most ``S <= 15`` significant digits (``-0.0832331``, ``0.348799``):
  ``"%.{S}g"``. Both reproduce every input token exactly: a decimal with ``<= 15`` significant
  digits survives the round trip through the nearest double;
* otherwise (exponents, ``nan``, ``> 15`` digits): ``"%r"``, Python's shortest round-trip form.

``"f32"`` means the shortest text that reads back as the same float32 (for float32 data written
as text: ``float32(0.1)`` is written ``0.1``, not ``0.10000000149011612``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

__all__ = ["F32", "Digits", "default_spec", "fine_enough", "format_column", "write_rows"]

F32 = "f32"
ROWS_PER_CHUNK = 65536

_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 32]] = True
_DIGIT = np.zeros(256, dtype=bool)
_DIGIT[48:58] = True
_NONZERO = np.zeros(256, dtype=bool)
_NONZERO[49:58] = True
_PLAIN = np.zeros(256, dtype=bool)  # characters of a decimal number (with an exponent)
_PLAIN[[43, 45, 46, 69, 101]] = True
_PLAIN[48:58] = True
_EXP = np.zeros(256, dtype=bool)
_EXP[[69, 101]] = True


class Digits:
    """Per-column digit statistics of whitespace-separated number tables."""

    def __init__(self, width: int) -> None:
        self.width = width
        self.dmin = np.full(width, 10**6, dtype=np.int64)
        self.dmax = np.zeros(width, dtype=np.int64)
        self.smax = np.zeros(width, dtype=np.int64)
        self.other = np.zeros(width, dtype=bool)
        self.exp = np.zeros(width, dtype=bool)

    def update(self, block: bytes | memoryview, first_column: int = 0) -> None:
        """Add a block of complete rows (blank lines allowed; every row has ``width`` tokens)."""
        raw = np.frombuffer(block, dtype=np.uint8)
        if raw.size == 0:
            return
        space = _SPACE[raw]
        start = ~space
        start[1:] &= space[:-1]
        end = ~space
        end[:-1] &= space[1:]
        s = np.flatnonzero(start)
        e = np.flatnonzero(end)  # index of each token's last character
        if s.size == 0:
            return
        col = (np.arange(s.size) + first_column) % self.width
        cs_digit = np.cumsum(_DIGIT[raw], dtype=np.int64)
        cs_plain = np.cumsum(~_PLAIN[raw], dtype=np.int64)
        idx = np.arange(raw.size, dtype=np.int64)
        last_dot = np.maximum.accumulate(np.where(raw == 46, idx, -1))[e]
        big = raw.size + 1
        next_nz = np.minimum.accumulate(np.where(_NONZERO[raw], idx, big)[::-1])[::-1][s]
        next_e = np.minimum.accumulate(np.where(_EXP[raw], idx, big)[::-1])[::-1][s]
        exp = next_e <= e
        e = np.where(exp, next_e - 1, e)  # the mantissa's last character

        def between(cs: NDArray[np.int64], a: NDArray[np.int64], b: NDArray[np.int64]) -> Any:
            return cs[b] - np.where(a > 0, cs[np.maximum(a - 1, 0)], 0)

        head = raw[np.minimum(s + np.isin(raw[s], (43, 45)), raw.size - 1)]
        named = ((head | 32) == ord("n")) | ((head | 32) == ord("i"))  # nan, inf: any spec
        other = (between(cs_plain, s, e) > 0) & ~named
        has_dot = last_dot >= s
        decimals = np.where(has_dot, e - last_dot, 0)
        digits = between(cs_digit, s, e)
        lead = np.where(next_nz <= e, between(cs_digit, s, np.minimum(next_nz, e)) - 1, digits - 1)
        sig = np.maximum(digits - lead, 1)
        for c in range(self.width):
            m = (col == c) & ~named
            if not m.any():
                continue
            self.other[c] |= bool(other[m].any())
            self.exp[c] |= bool(exp[m].any())
            self.dmin[c] = min(self.dmin[c], int(decimals[m].min()))
            self.dmax[c] = max(self.dmax[c], int(decimals[m].max()))
            self.smax[c] = max(self.smax[c], int(sig[m].max()))

    def specs(self) -> tuple[str, ...]:
        """One printf spec per column (see the module docstring)."""
        out = []
        for c in range(self.width):
            if self.other[c] or self.smax[c] > 15 or self.smax[c] == 0:
                out.append("%r")
            elif self.dmin[c] == self.dmax[c] and not self.exp[c]:
                out.append(f"%.{int(self.dmax[c])}f")
            else:
                out.append(f"%.{int(self.smax[c])}g")
        return tuple(out)


#: The coarsest resolution a text spec may have, relative to the data's extent: an input of
#: integers (``v 1 2 3``) must not quantize smoothed points to integers, while six decimals on
#: an object of a few units stay six decimals.
RELATIVE_RESOLUTION = 1e-5


def fine_enough(spec: str, values: NDArray[np.float64], extent: float) -> str:
    """``spec``, refined until its resolution is at most ``1e-5 * extent`` (see above)."""
    if spec in ("%r", F32, "%d") or values.size == 0:
        return spec
    need = RELATIVE_RESOLUTION * (extent if extent > 0 else max(float(np.max(np.abs(values))), 1.0))
    want = int(np.ceil(-np.log10(need)))  # decimals giving that resolution
    if spec.endswith("f"):
        d = int(spec[2:-1])
        return spec if d >= want else f"%.{want}f"
    top = float(np.max(np.abs(values)))
    if top == 0:
        return spec
    s = int(spec[2:-1])
    digits = int(np.floor(np.log10(top))) + 1 + want
    if digits <= s:
        return spec
    return f"%.{digits}g" if digits <= 15 else "%r"


def default_spec(dtype: np.dtype[Any]) -> str:
    """The spec for a column of ``dtype`` with no digits measured: exact and shortest."""
    if dtype.kind in "iub":
        return "%d"
    if dtype == np.float32 or dtype == np.float16:
        return F32
    return "%r"


def _float32_text(values: NDArray[Any]) -> list[str]:
    """Shortest text reading back as the same float32 (6 to 9 significant digits)."""
    v32 = np.asarray(values, dtype=np.float32)
    v = v32.astype(np.float64).tolist()
    out = [f"{x:.6g}" for x in v]
    for p in (7, 8, 9):
        with np.errstate(over="ignore", invalid="ignore"):
            back = np.array(out, dtype=np.float64).astype(np.float32)
        bad = np.flatnonzero((back != v32) & ~np.isnan(v32))
        if bad.size == 0:
            break
        fmt = f"%.{p}g"
        for i in bad.tolist():
            out[i] = fmt % v[i]
    return out


def format_column(values: NDArray[Any], spec: str) -> list[str]:
    """Each value of a 1-D column as text in ``spec``."""
    if spec == F32:
        return _float32_text(values)
    if spec == "%d":
        return [str(x) for x in np.asarray(values).astype(np.int64).tolist()]
    if spec == "%r":
        return [repr(x) for x in np.asarray(values, dtype=np.float64).tolist()]
    return [spec % x for x in np.asarray(values, dtype=np.float64).tolist()]


def write_rows(
    out: BinaryIO,
    columns: Sequence[tuple[NDArray[Any], str]],
    *,
    prefix: str = "",
    sep: str = " ",
    suffix: str = "",
    n: int | None = None,
) -> None:
    """Write rows ``prefix c0 sep c1 ... suffix\\n``, one column per (values, spec), in chunks."""
    if n is None:
        n = len(columns[0][0]) if columns else 0
    for s in range(0, n, ROWS_PER_CHUNK):
        cols = [format_column(v[s : s + ROWS_PER_CHUNK], spec) for v, spec in columns]
        rows = [prefix + sep.join(r) + suffix for r in zip(*cols, strict=True)]
        out.write(("\n".join(rows) + "\n").encode("ascii"))
