"""Every peer at its own defaults: what a user gets without ground truth (issue 21).

Each swept peer of :mod:`benchmarks.quality.peers` gets a twin named ``"<name> (defaults)"``
with a one-setting grid: the library's own default arguments (checked against the signatures of
trimesh 4.12, Open3D 0.20, pymeshlab 2025.7, PyVista 0.49). Where the swept wrapper overrides
an option the sweep needs (PyVista's edge and feature angles), the defaults' run calls the
library with no option at all. Open3D's cloud MLS and bilateral filters default to absolute
radii (0.05 units), which is what a user gets. PyMeshLab's APSS and RIMLS run at their default
scale through the two-mesh call of ``peers._ml_mls`` (the filter's own default call crashes).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.quality.peers import QUALITY_PEERS, FloatArray, QualityPeer, Run, _polydata
from benchmarks.quality.shapes import Shape

__all__ = ["DEFAULTS", "DEFAULT_PEERS"]

SUFFIX = " (defaults)"


def _pv_sinc_defaults(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    out = _polydata(P, shape).smooth_taubin()
    return np.asarray(out.points, dtype=np.float64)[:, : P.shape[1]]


def _pv_laplacian_defaults(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    out = _polydata(P, shape).smooth()
    return np.asarray(out.points, dtype=np.float64)[:, : P.shape[1]]


def _o3d_cloud(P: FloatArray) -> Any:
    import open3d as o3d

    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))


def _o3d_mls_defaults(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    return np.asarray(_o3d_cloud(P).smooth_mls().points)


def _o3d_bilateral_defaults(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    return np.asarray(_o3d_cloud(P).smooth_bilateral().points)


#: peer name -> (run or None for the swept peer's own run, the default setting)
DEFAULTS: dict[str, tuple[Run | None, dict[str, Any]]] = {
    "trimesh filter_laplacian": (None, {"lambda": 0.5, "iterations": 10,
                                        "volume_constraint": True}),
    # trimesh's 10 iterations are 5 shrink + 5 inflate steps; nu = 0.5
    "trimesh filter_taubin": (None, {"iterations": 5, "lambda": 0.5, "mu": -0.5}),
    "trimesh filter_humphrey": (None, {"iterations": 10, "alpha": 0.1, "beta": 0.5}),
    "Open3D filter_smooth_laplacian": (None, {"iterations": 1, "lambda": 0.5}),
    "Open3D filter_smooth_taubin": (None, {"iterations": 1, "lambda": 0.5, "mu": -0.53}),
    "PyMeshLab Laplacian": (None, {"iterations": 3, "cotangent": True}),
    "PyMeshLab Taubin": (None, {"iterations": 10, "lambda": 0.5, "mu": -0.53}),
    "PyMeshLab two-step": (None, {"iterations": 3, "normalthr": 60}),
    "PyMeshLab HC Laplacian": (None, {"iterations": 1}),
    "PyVista windowed-sinc": (_pv_sinc_defaults, {}),
    "PyVista Laplacian": (_pv_laplacian_defaults, {}),
    "Open3D cloud Laplacian": (None, {"iterations": 10, "lambda": 0.5, "knn": 20}),
    "Open3D cloud Taubin": (None, {"iterations": 10, "lambda": 0.5, "mu": -0.53, "knn": 20}),
    "Open3D cloud MLS": (_o3d_mls_defaults, {}),
    "Open3D cloud bilateral": (_o3d_bilateral_defaults, {}),
    "PyMeshLab APSS": (None, {"method": "apss", "filterscale": 2.0, "spherical": 1.0}),
    "PyMeshLab RIMLS": (None, {"method": "rimls", "filterscale": 2.0, "sigman": 0.75}),
}


def _one(setting: dict[str, Any]) -> Callable[[Shape, bool], list[dict[str, Any]]]:
    def grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
        return [dict(setting)]

    return grid


def _twin(peer: QualityPeer) -> QualityPeer:
    run, setting = DEFAULTS[peer.name]
    return QualityPeer(peer.name + SUFFIX, peer.package, peer.kinds, run or peer.run,
                       _one(setting), peer.isolated, peer.revision)


#: The defaults' twins, in the order of ``QUALITY_PEERS``.
DEFAULT_PEERS: list[QualityPeer] = [_twin(p) for p in QUALITY_PEERS]
