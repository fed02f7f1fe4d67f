"""Make the repository's ``benchmarks`` package importable under plain ``pytest`` too.

``benchmarks/`` is not part of the installed distribution (only ``service`` is), and only
``python -m pytest`` puts the working directory on ``sys.path``.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[2])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
