"""In-process caches: built operators (neighbourhoods + Laplacian), CHOLMOD analyses and the
last normal frames.

The same mesh is often smoothed several times (several tau, the web page's re-runs, a batch of
scans of one part). Both caches are keyed by a digest of what the cached object depends on, so
any change of points, connectivity or build parameters (operators), or of the sparsity pattern
of ``K(lambda)`` (analyses: it follows the connectivity and the fixed set) misses the cache —
there is no invalidation to forget. Entries are evicted least recently used, and a cached
analysis is handed out as a copy (a factor holds its numeric values in place).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import numpy as np

__all__ = ["LRU", "analyses", "analysis_of", "clear", "digest", "frames", "operators"]

T = TypeVar("T")


def digest(*parts: object) -> str:
    """Digest of arrays (shape, dtype and bytes) and plain values."""
    h = hashlib.blake2b(digest_size=16)
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(repr((part.shape, part.dtype.str)).encode())
            h.update(np.ascontiguousarray(part).data)
        else:
            h.update(repr(part).encode())
        h.update(b"|")
    return h.hexdigest()


class LRU(Generic[T]):
    """A small thread-safe least-recently-used map.

    Parameters
    ----------
    size : int
        Entries kept.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self._data: OrderedDict[str, T] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get_or_make(
        self, key: str, make: Callable[[], T], copy: Callable[[T], T] | None = None
    ) -> T:
        """The cached value for ``key`` (through ``copy`` if given), made and stored on a miss."""
        with self._lock:
            if key in self._data:
                self._data.move_to_end(key)
                self.hits += 1
                value = self._data[key]
                return copy(value) if copy is not None else value
            self.misses += 1
        value = make()
        with self._lock:
            self._data[key] = value
            while len(self._data) > self.size:
                self._data.popitem(last=False)
        return copy(value) if copy is not None else value

    def clear(self) -> None:
        with self._lock:
            self._data.clear()
            self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._data)


operators: LRU[Any] = LRU(2)
"""Built :class:`~service.core.pipeline.SmoothingOperator` objects, by geometry and build params."""
analyses: LRU[Any] = LRU(4)
"""CHOLMOD symbolic analyses, by sparsity pattern and ordering."""
frames: LRU[Any] = LRU(1)
"""The last normal frames (:func:`~service.core.system.displacement.normal_frames`): the normal
system and the tangential step of one run ask for the same ones."""


def clear() -> None:
    """Empty the caches."""
    operators.clear()
    analyses.clear()
    frames.clear()


def analysis_of(pattern: Any, ordering: str | None = None) -> Any:
    """A copy of the cached CHOLMOD analysis of the pattern of ``pattern`` (CSC), made once."""
    from service.core.linalg.solver import analyze, ordering_for

    ordering = ordering if ordering is not None else ordering_for(pattern.shape[0])
    key = digest(pattern.indptr, pattern.indices, pattern.shape, ordering)
    return analyses.get_or_make(key, lambda: analyze(pattern, ordering), copy=lambda f: f.copy())
