"""OBJ face and polyline statements: indices resolved (1-based, negative), checked, collected."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError

__all__ = ["Faces", "resolve"]


def _fail(line: int, message: str) -> FormatError:
    return FormatError(f"line {line}: {message}", fmt="obj", line=line)


def resolve(
    raw: NDArray[np.int64],
    before: NDArray[np.int64],
    total: int | None,
    numbers: NDArray[np.int64],
    counts: NDArray[np.int64],
    what: str,
    absent_ok: bool,
    thing: str = "vertex",
) -> NDArray[np.int64]:
    """0-based indices from OBJ's 1-based / negative ones; ``-1`` for absent (0) when allowed."""
    flat = np.where(raw > 0, raw - 1, before + raw)
    absent = raw == 0
    bad = ((flat < 0) | absent) & ~(absent & absent_ok)
    if total is not None:
        bad |= flat >= total
    if absent_ok:
        flat = np.where(absent, -1, flat)
    if bad.any():
        pos = int(np.flatnonzero(bad)[0])
        row = int(np.searchsorted(np.cumsum(counts), pos, side="right"))
        line = int(numbers[row])
        if raw[pos] == 0:
            raise _fail(line, "index 0 is not valid (OBJ indices start at 1)")
        if raw[pos] < 0:
            raise _fail(
                line,
                f"{what} refers to relative {thing} {int(raw[pos])} but only {int(before[pos])}"
                " precede it",
            )
        raise _fail(line, f"{what} refers to {thing} {int(raw[pos])} but the file has {total}")
    return flat


@dataclass
class Faces:
    """Face or polyline statements of the whole file (resolved where the block allows)."""

    v: list[NDArray[np.int64]] = field(default_factory=list)
    vt: list[NDArray[np.int64]] = field(default_factory=list)
    vn: list[NDArray[np.int64]] = field(default_factory=list)
    counts: list[NDArray[np.int64]] = field(default_factory=list)
    numbers: list[NDArray[np.int64]] = field(default_factory=list)

    def add(
        self,
        corner_columns: tuple[NDArray[np.int64], NDArray[np.int64], int],
        numbers: list[int],
        before: Any,
        what: str,
    ) -> None:
        cols, counts, m = corner_columns
        nums = np.asarray(numbers, dtype=np.int64)
        rep = [np.repeat(b, counts) for b in before]
        self.v.append(resolve(cols[:, 0], rep[0], None, nums, counts, what, False))
        if m >= 2:
            self.vt.append(resolve(cols[:, 1], rep[1], None, nums, counts, what, True, "vt"))
        if m == 3:
            self.vn.append(resolve(cols[:, 2], rep[2], None, nums, counts, what, True, "vn"))
        self.counts.append(counts)
        self.numbers.append(nums)

    def finish(
        self, totals: tuple[int, int, int], what: str, notes: list[str]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64] | None]:
        """Vertex indices, corners per statement, normal indices (``None``: not every corner)."""
        counts = np.concatenate(self.counts)
        nums = np.concatenate(self.numbers)
        flat = np.concatenate(self.v)
        _check_upper(flat, totals[0], nums, counts, what)
        vn = None
        if self.vn and len(self.vn) == len(self.v):
            vn = np.concatenate(self.vn)
            if vn.max(initial=-1) >= totals[2]:
                notes.append(f"{what} normal indices beyond the {totals[2]} 'vn' lines: ignored")
                vn = None
        if self.vt and np.concatenate(self.vt).max(initial=-1) >= totals[1]:
            notes.append(f"{what} texture indices beyond the {totals[1]} 'vt' lines")
        return flat, counts, vn

    def texture(self, total: int) -> NDArray[np.int64] | None:
        """Every corner's 0-based ``vt`` index, or ``None`` unless every corner has a valid one."""
        if not self.vt or len(self.vt) != len(self.v):
            return None
        vt = np.concatenate(self.vt)
        return vt if vt.size and vt.min() >= 0 and vt.max() < total else None


def _check_upper(
    flat: NDArray[np.int64],
    total: int,
    numbers: NDArray[np.int64],
    counts: NDArray[np.int64],
    what: str,
) -> None:
    bad = flat >= total
    if bad.any():
        pos = int(np.flatnonzero(bad)[0])
        row = int(np.searchsorted(np.cumsum(counts), pos, side="right"))
        raise _fail(
            int(numbers[row]),
            f"{what} refers to vertex {int(flat[pos]) + 1} but the file has {total} vertices",
        )
