"""The rules that tie the automatic choices together, written once (pure: no numpy).

``displacement="auto"`` moves meshes and point clouds along their normals and curves freely (the
quality benchmark's choice), but always freely for ``method="windowed-sinc"`` (Taubin's filter of
the points themselves) and ``tau="gcv"`` (cross-validation assumes the data are the points), and
normally only up to :data:`AUTO_NORMAL_MAX_CODIM` normal directions. A mesh's boundary rows follow
the displacement (:func:`boundary_mode`): ``"curve"`` where points move freely, ``"ring"`` with
normal displacement. The plan (:mod:`service.core.plan`), the operator's boundary rows
(:mod:`service.core.operator.boundary`) and the memory model (:mod:`service.core.linalg.resources`)
all read these functions, so the plan can never record one displacement and build the boundary
rows of the other (issue 38).
"""

from __future__ import annotations

__all__ = [
    "AUTO_NORMAL_MAX_CODIM",
    "DEFAULT_DISPLACEMENT",
    "boundary_mode",
    "codimension_of",
    "data_weight_gates",
    "displacement_mode",
    "free_only",
]

#: ``displacement="auto"`` per kind of input (chosen on the quality benchmark).
DEFAULT_DISPLACEMENT = {"mesh": "normal", "curve": "free", "cloud": "normal"}

#: ``displacement="auto"`` takes normal displacement only up to this codimension: its system has
#: ``r x r`` blocks per Laplacian entry (assembly ``O(nnz r^2)``, factor ``O(r^3)`` times the free
#: system's, which solves ``s`` columns with one factor). Surfaces in 3-D and curves in 2-D have
#: ``r = 1``, a cloud in 4-D ``r = 2``; a cloud in 300-D would have ``r = 298`` (minutes for 50
#: points) while in ``s - 2`` of ``s`` directions normal and free displacement barely differ.
AUTO_NORMAL_MAX_CODIM = 2


def free_only(method: str, tau_rule: str) -> bool:
    """Whether the run can only displace freely (windowed-sinc, GCV)."""
    return method == "windowed-sinc" or tau_rule == "gcv"


def codimension_of(kind: str, dim: int) -> int:
    """Normal directions per point: ``s - 2`` for meshes, ``s - 1`` for curves, ``s - 2`` for
    clouds in 3-D and more (``s - 1`` in 2-D)."""
    manifold = {"mesh": 2, "curve": 1}.get(kind, min(2, dim - 1))
    return max(dim - manifold, 0)


def displacement_mode(displacement: str, kind: str, dim: int, method: str, tau_rule: str) -> str:
    """``"free"`` or ``"normal"``: the displacement of a run (``displacement`` resolved when it
    is ``"auto"``)."""
    if displacement != "auto":
        return displacement
    if free_only(method, tau_rule):
        return "free"
    mode = DEFAULT_DISPLACEMENT[kind]
    r = codimension_of(kind, dim)
    return mode if mode == "free" or 1 <= r <= AUTO_NORMAL_MAX_CODIM else "free"


def boundary_mode(boundary: str, displacement: str) -> str:
    """``"curve"`` or ``"ring"``: a mesh's boundary rows (``boundary`` resolved when it is
    ``"auto"``) for the resolved ``displacement``."""
    if boundary != "auto":
        return boundary
    return "curve" if displacement == "free" else "ring"


def data_weight_gates(
    robust: str, noise_weights: str, tau_rule: str, user_weights: bool
) -> tuple[str, str]:
    """The robust rule and the noise weights a run tries (``"none"``: the gate is shut).

    ``"auto"`` opens with the automatic tau on inputs without weights of their own only (a given
    tau, rms or lambda is a budget in the user's weights); a named rule (``"huber"``,
    ``"tukey"``, ``"local"``) always.
    """
    automatic = tau_rule == "auto" and not user_weights
    return (
        robust if robust != "auto" or automatic else "none",
        noise_weights if noise_weights != "auto" or automatic else "none",
    )
