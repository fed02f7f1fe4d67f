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

import re
from collections.abc import Sequence
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

__all__ = ["F32", "Digits", "default_spec", "fine_enough", "format_column", "write_rows"]

F32 = "f32"
ROWS_PER_CHUNK = 65536

_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 32]] = True
_PLAIN = np.zeros(256, dtype=bool)  # characters of a fixed-point number
_PLAIN[[43, 45, 46]] = True
_PLAIN[48:58] = True
_POW10 = 10.0 ** np.arange(309)
_MANTISSA = re.compile(r"[+-]?(\d*)\.?(\d*)")


class Digits:
    """Per-column digit statistics of whitespace-separated number tables.

    For each token: its decimals ``D`` (from the position of its ``.``) and its significant
    digits ``S``, the digit count of the integer ``round(|value| * 10**D)`` (leading zeros do not
    count, trailing ones do: ``0.500`` has 3). Tokens with an exponent are measured on their
    mantissa (rare: a Python loop); ``nan`` / ``inf`` fit every spec and are left out. Only
    byte-level passes of numpy plus arithmetic on the parsed values: cheap next to parsing.
    """

    def __init__(self, width: int) -> None:
        self.width = width
        self.dmin = np.full(width, 10**6, dtype=np.int64)
        self.dmax = np.zeros(width, dtype=np.int64)
        self.smax = np.zeros(width, dtype=np.int64)
        self.other = np.zeros(width, dtype=bool)
        self.exp = np.zeros(width, dtype=bool)

    def update(self, block: bytes, values: NDArray[np.float64] | None = None) -> None:
        """Add a block of complete rows (blank lines allowed; every row has ``width`` tokens).

        ``values``: the block's numbers as parsed, ``(rows, width)`` (parsed here if omitted).
        """
        raw = np.frombuffer(block, dtype=np.uint8)
        space = _SPACE[raw]
        start = ~space
        start[1:] &= space[:-1]
        end = ~space
        end[:-1] &= space[1:]
        s, e = np.flatnonzero(start), np.flatnonzero(end)
        if s.size == 0:
            return
        if s.size % self.width:
            raise ValueError("Digits.update needs rows of exactly `width` tokens")
        if values is None:
            values = np.array(block.split(), dtype=np.float64)
        vals = np.asarray(values, dtype=np.float64).reshape(-1)
        token_of = np.cumsum(start, dtype=np.int32)  # 1 + index of the token at each byte
        dots = np.flatnonzero(raw == 46)
        decimals = np.zeros(s.size, dtype=np.int64)
        tok = token_of[dots] - 1
        decimals[tok] = e[tok] - dots
        odd = np.zeros(s.size, dtype=bool)  # exponents, nan, inf, anything not d.ddd
        bad = np.flatnonzero(~_PLAIN[raw] & ~space)
        if bad.size:
            odd[token_of[bad] - 1] = True
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            m = np.rint(np.abs(vals) * _POW10[np.minimum(decimals, 308)])
            sig = np.where(m >= 1, np.floor(np.log10(np.maximum(m, 1))) + 1, 1).astype(np.int64)
        skip = odd.copy()
        for i in np.flatnonzero(odd).tolist():
            self._odd(block[s[i] : e[i] + 1], i % self.width, skip, i, sig, decimals)
        shape = (-1, self.width)
        keep = ~skip.reshape(shape)
        big = np.int64(10**6)
        self.dmin = np.minimum(self.dmin, np.where(keep, decimals.reshape(shape), big).min(axis=0))
        self.dmax = np.maximum(self.dmax, np.where(keep, decimals.reshape(shape), 0).max(axis=0))
        counted = ~(odd & skip).reshape(shape)
        self.smax = np.maximum(self.smax, np.where(counted, sig.reshape(shape), 0).max(axis=0))

    def _odd(
        self,
        token: bytes,
        col: int,
        skip: NDArray[np.bool_],
        i: int,
        sig: NDArray[np.int64],
        decimals: NDArray[np.int64],
    ) -> None:
        """A token with an exponent (measured on its mantissa) or a name (nan, inf, other)."""
        text = token.decode("ascii", errors="replace").lower()
        if text.lstrip("+-") in ("nan", "inf", "infinity"):
            return  # any spec writes these; they say nothing about digits
        mant, sep, _ = text.partition("e")
        m = _MANTISSA.fullmatch(mant)
        if not sep or m is None:
            self.other[col] = True
            return
        self.exp[col] = True
        digits = (m[1] + m[2]).lstrip("0")
        sig[i] = max(len(digits), 1)
        decimals[i] = len(m[2])
        skip[i] = False  # counted for S (not for fixed decimals: the column is %g now)

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
    if np.all(values == np.round(values)):  # integers lose nothing (a plane's z = 0 stays "0")
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
