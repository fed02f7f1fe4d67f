"""The free-vs-normal displacement rule, written once (pure: no numpy).

``displacement="auto"`` moves meshes and point clouds along their normals and curves freely (the
quality benchmark's choice), but always freely for ``method="windowed-sinc"`` (Taubin's filter of
the points themselves) and ``tau="gcv"`` (cross-validation assumes the data are the points).
The callers refine it with what they know: the codimension cap of
:func:`service.core.system.displacement.resolve_displacement`, the boundary rule of
:func:`service.core.operator.boundary.boundary_rule` and the memory model of
:mod:`service.core.linalg.resources`.
"""

from __future__ import annotations

__all__ = ["DEFAULT_DISPLACEMENT", "auto_displacement", "free_only"]

#: ``displacement="auto"`` per kind of input (chosen on the quality benchmark).
DEFAULT_DISPLACEMENT = {"mesh": "normal", "curve": "free", "cloud": "normal"}


def free_only(method: str, tau_rule: str) -> bool:
    """Whether the run can only displace freely (windowed-sinc, GCV)."""
    return method == "windowed-sinc" or tau_rule == "gcv"


def auto_displacement(kind: str, method: str, tau_rule: str) -> str:
    """``"free"`` or ``"normal"``: what ``displacement="auto"`` means for this kind and run."""
    return "free" if free_only(method, tau_rule) else DEFAULT_DISPLACEMENT[kind]
