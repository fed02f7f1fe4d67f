"""The in-memory form of one parsed PLY element (shared by the ASCII and binary readers)."""

from __future__ import annotations

from typing import Any

from numpy.typing import NDArray

__all__ = ["Column", "ElementData"]

# what one element yields: scalar property -> 1-D array; list property -> (flat items, counts);
# counts are non-negative integers in a compact dtype; items may be a (count, k) view when every
# list has k items (binary files), else flat
Column = NDArray[Any] | tuple[NDArray[Any], NDArray[Any]]
ElementData = dict[str, Column]
