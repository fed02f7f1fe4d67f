"""The in-memory form of one parsed PLY element (shared by the ASCII and binary readers)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["Column", "ElementData"]

# what one element yields: scalar property -> 1-D array; list property -> (flat items, counts)
Column = NDArray[np.generic] | tuple[NDArray[np.generic], NDArray[np.int64]]
ElementData = dict[str, Column]
