"""The quality benchmark's markdown table (filled in by render())."""

from __future__ import annotations

from typing import Any

__all__ = ["render"]


def render(doc: dict[str, Any]) -> str:
    """Placeholder until the table is written."""
    return "\n".join(c["key"] for c in doc["cases"])
