"""Reader limits: how many points a file may declare, how much memory reading it may take.

Every reader that learns a count before allocating (LAS/LAZ and PLY headers, PCD ``POINTS``,
binary STL triangles, the lines of a text file, a DXF's flattened points) calls
:func:`check_points` with the count and the bytes a point will cost, so a file whose header
claims 2**32 points is refused before anything is allocated, on every path: the ordinary readers
(:func:`service.io.read_geometry`), the streamed ones (:mod:`service.io.stream`), the CLI, the
library and the server's parse process.

The limits in force are a context variable (:func:`reading`): ``read_geometry(...,
limits=ReadLimits(max_points=..., max_memory=...))`` and
:func:`service.io.stream.read_coordinates` set them for the duration of the read; the CLI
takes ``--max-points`` and
``--max-memory``. Defaults need no settings: :data:`DEFAULT_MAX_POINTS` points and 3/4 of the
machine's memory (or of the address-space limit, if lower).
"""

from __future__ import annotations

import contextlib
import os
import resource
from collections.abc import Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from typing import ClassVar

from service.io.errors import FormatError

__all__ = [
    "DEFAULT_MAX_POINTS",
    "InputTooLarge",
    "ReadLimits",
    "check_points",
    "current",
    "default_max_memory",
    "limits_of",
    "parse_count",
    "reading",
]

#: Points a file may hold unless the caller raises the limit (500x the server's default).
DEFAULT_MAX_POINTS = 1_000_000_000


def default_max_memory() -> int:
    """3/4 of the physical memory, or of the soft address-space limit if that is lower."""
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):  # pragma: no cover - not Linux
        total = 8 << 30
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY and soft > 0:
        total = min(total, soft)
    return int(total * 3 // 4)


class InputTooLarge(FormatError):
    """A file that declares more points, or needs more memory to read, than the limits allow."""

    code: ClassVar[str] = "input-too-large"
    title: ClassVar[str] = "Input too large to read"
    status: ClassVar[int] = 413
    exit_code: ClassVar[int] = 3  # the CLI's table: the input cannot be read


def _size(n: float) -> str:
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} bytes"


@dataclass(frozen=True)
class ReadLimits:
    """Bounds of one read. ``None`` for a member: no bound of that kind.

    Attributes
    ----------
    max_points : int or None
        Points (vertices) a file may hold.
    max_memory : int or None
        Bytes the reader's estimate (made before allocating) may reach; default
        :func:`default_max_memory`.
    """

    max_points: int | None = DEFAULT_MAX_POINTS
    max_memory: int | None = -1  # -1: default_max_memory(), resolved when checked

    HINT: ClassVar[str] = (
        "raise the limit with --max-points / --max-memory (library: "
        "read_geometry(..., limits=ReadLimits(...)))"
    )

    def memory(self) -> int | None:
        """The memory bound in bytes (the default resolved)."""
        return default_max_memory() if self.max_memory == -1 else self.max_memory

    def check(self, n: int, bytes_per_point: float, fmt: str | None, what: str = "points") -> None:
        """Raise :class:`InputTooLarge` if ``n`` points (costing ``bytes_per_point`` each while
        read) exceed a bound."""
        if self.max_points is not None and n > self.max_points:
            raise InputTooLarge(
                f"the file holds {n} {what}, more than the limit of {self.max_points} points; "
                f"{self.HINT}",
                fmt=fmt,
            )
        limit = self.memory()
        need = float(n) * float(bytes_per_point)
        if limit is not None and need > limit:
            raise InputTooLarge(
                f"reading the file's {n} {what} needs about {_size(need)}, more than the limit "
                f"of {_size(limit)}; {self.HINT}",
                fmt=fmt,
            )


_CURRENT: ContextVar[ReadLimits | None] = ContextVar("geosmooth_read_limits", default=None)


def current() -> ReadLimits:
    """The limits in force (:func:`reading` sets them; else the defaults)."""
    return _CURRENT.get() or ReadLimits()


@contextlib.contextmanager
def reading(limits: ReadLimits | None) -> Iterator[ReadLimits]:
    """Run a read under ``limits`` (``None``: the ones in force)."""
    if limits is None:
        yield current()
        return
    token = _CURRENT.set(limits)
    try:
        yield limits
    finally:
        _CURRENT.reset(token)


def check_points(n: int, bytes_per_point: float, fmt: str | None, what: str = "points") -> None:
    """:meth:`ReadLimits.check` with the limits in force."""
    current().check(n, bytes_per_point, fmt, what)


_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_count(text: str, *, units: bool = False) -> int | None:
    """A limit as the command line gives it: an integer (``units``: with an optional ``K``,
    ``M``, ``G`` or ``T`` suffix, powers of 1024, an optional ``B``/``iB``), ``0`` or ``none``
    for no bound.

    Raises
    ------
    ValueError
        Anything else (the message says what is expected).
    """
    raw = text.strip().upper().removesuffix("IB").removesuffix("B")
    if raw in ("NONE", "0"):
        return None
    unit = raw[-1:] if units and raw[-1:] in _UNITS else ""
    number = raw[: len(raw) - len(unit)]
    try:
        value = float(number) if unit else int(number.replace("_", ""))
    except ValueError:
        kind = "a byte count such as 8G, 512M or 1000000" if units else "an integer"
        raise ValueError(f"expected {kind}, or 'none', got {text!r}") from None
    if value < 0:
        raise ValueError(f"must not be negative, got {text!r}")
    return int(value * _UNITS[unit])


def limits_of(
    max_points: str | int | None = None, max_memory: str | int | None = None
) -> ReadLimits:
    """:class:`ReadLimits` from optional values (``None``: the default of that bound)."""
    base = ReadLimits()
    points = (
        base.max_points
        if max_points is None
        else (parse_count(max_points) if isinstance(max_points, str) else max_points or None)
    )
    memory = (
        base.max_memory
        if max_memory is None
        else (
            parse_count(max_memory, units=True)
            if isinstance(max_memory, str)
            else max_memory or None
        )
    )
    return ReadLimits(max_points=points, max_memory=memory)
