"""Peer filters for the quality benchmark, each with its parameter family.

Meshes: trimesh (Laplacian, Taubin, Humphrey), Open3D (Laplacian, Taubin), PyMeshLab
(Laplacian, Taubin, two-step, HC Laplacian: the mesh filters of :mod:`benchmarks.peers`, reused
here), PyVista / VTK windowed-sinc (``smooth_taubin``) and Laplacian (``smooth``).
Curves: PyVista windowed-sinc and Laplacian on line cells (the only peers that smooth polylines).
Point clouds: Open3D's point-cloud filters (k-NN Laplacian and Taubin, MLS-style tangent-plane
projection, bilateral) and PyMeshLab's MLS projections (APSS, RIMLS) on meshes and clouds.

PyMeshLab's MLS filters run in a child process (a crash is recorded, not fatal): called on one
mesh (the filter's default) they crash the interpreter in pymeshlab 2022.2 - 2025.7; with the
point set and the points to project as two meshes they work (:func:`_ml_mls`).
Grids use the mean spacing ``h`` (known to any user), never the true noise level.
"""

from __future__ import annotations

import importlib.metadata
import itertools
import multiprocessing as mp
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks import peers as mesh_peers
from benchmarks.quality.shapes import Shape

__all__ = ["QUALITY_PEERS", "QualityPeer", "peer_versions"]

FloatArray = NDArray[np.float64]
Run = Callable[[FloatArray, Shape, dict[str, Any]], FloatArray]

ITERS = (1, 2, 3, 5, 8, 13, 21, 34, 55, 89)
ITERS_SMALL = (1, 2, 4, 8, 16, 32)


@dataclass
class QualityPeer:
    """A peer filter: ``run(points, shape, setting)`` and ``grid(shape, quick)``."""

    name: str
    package: str
    kinds: tuple[str, ...]
    run: Run
    grid: Callable[[Shape, bool], Iterable[dict[str, Any]]]
    isolated: bool = False  # run in a child process (may crash the interpreter)
    revision: int = 0  # bumped when the wrapper changes (a new cache key for this peer only)


def _grid(**axes: Iterable[Any]) -> list[dict[str, Any]]:
    keys = list(axes)
    return [dict(zip(keys, v, strict=True)) for v in itertools.product(*axes.values())]


def _iters(shape: Shape, quick: bool) -> tuple[int, ...]:
    return ITERS_SMALL if quick or shape.n > 20000 else ITERS


def _mesh(f: mesh_peers.Filter) -> Run:
    def run(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
        assert shape.faces is not None
        return f(P, shape.faces, s)

    return run


# --- PyVista / VTK -----------------------------------------------------------------------------


def _polydata(P: FloatArray, shape: Shape) -> Any:
    import pyvista as pv

    P3 = P if P.shape[1] == 3 else np.column_stack([P, np.zeros((len(P), 3 - P.shape[1]))])
    if shape.faces is not None:
        cells = np.column_stack([np.full(len(shape.faces), 3), shape.faces]).ravel()
        return pv.PolyData(P3, faces=cells)
    assert shape.edges is not None
    cells = np.column_stack([np.full(len(shape.edges), 2), shape.edges]).ravel()
    return pv.PolyData(P3, lines=cells)


def _pv_sinc(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    # edge_angle 180: noisy polyline vertices (and mesh boundary vertices) are not taken as
    # corners to keep fixed (with VTK's default of 15 degrees a noisy curve does not move)
    out = _polydata(P, shape).smooth_taubin(
        n_iter=s["n_iter"], pass_band=s["pass_band"], non_manifold_smoothing=True,
        normalize_coordinates=True, edge_angle=180.0, feature_angle=180.0,
    )
    return np.asarray(out.points, dtype=np.float64)[:, : P.shape[1]]


def _pv_laplacian(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    out = _polydata(P, shape).smooth(
        n_iter=s["n_iter"], relaxation_factor=s["relaxation"], edge_angle=180.0,
        feature_angle=180.0,
    )
    return np.asarray(out.points, dtype=np.float64)[:, : P.shape[1]]


def _sinc_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    # up to 400 iterations and pass bands down to 1e-4: on curves VTK's best needs them (torus
    # knot, iso 0.25 h: v 0.322 at most 40 iterations, 0.187 at 400 and pass band 0.003)
    bands = ((0.003, 0.01, 0.03, 0.1) if quick else
             (1e-4, 3e-4, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2))
    return _grid(n_iter=(10, 20) if quick else (10, 20, 40, 100, 200, 400), pass_band=bands)


def _pv_lap_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    return _grid(n_iter=_iters(shape, quick), relaxation=(0.1, 0.5) if not quick else (0.5,))


# --- Open3D point clouds -----------------------------------------------------------------------


def _o3d_cloud(P: FloatArray) -> Any:
    import open3d as o3d

    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))


def _o3d_pc_laplacian(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    out = _o3d_cloud(P).smooth_laplacian(iterations=s["iterations"], lambda_=s["lambda"],
                                         knn=s["knn"])
    return np.asarray(out.points)


def _o3d_pc_taubin(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    out = _o3d_cloud(P).smooth_taubin(iterations=s["iterations"], lambda_=s["lambda"],
                                      mu=s["mu"], knn=s["knn"])
    return np.asarray(out.points)


def _o3d_pc_mls(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    import open3d as o3d

    param = o3d.geometry.KDTreeSearchParamHybrid(radius=s["radius_h"] * shape.h, max_nn=s["max_nn"])
    X = P
    for _ in range(s["passes"]):
        X = np.asarray(_o3d_cloud(X).smooth_mls(search_param=param).points)
    return X


def _o3d_pc_bilateral(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    import open3d as o3d

    h = shape.h
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=3 * s["sigma_s_h"] * h, max_nn=60)
    X = P
    for _ in range(s["passes"]):
        pc = _o3d_cloud(X)
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(12))
        X = np.asarray(pc.smooth_bilateral(
            search_param=param, sigma_s=s["sigma_s_h"] * h, sigma_r=s["sigma_r_h"] * h).points)
    return X


def _knn_lap_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    return _grid(iterations=_iters(shape, quick), knn=(6, 12) if quick else (6, 10, 20),
                 **{"lambda": (0.5,)})


def _knn_taubin_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    return _grid(iterations=_iters(shape, quick), knn=(6, 12) if quick else (6, 10, 20),
                 **{"lambda": (0.5,), "mu": (-0.53,)})


def _mls_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    radii = (2.0, 3.0, 5.0) if quick else (1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
    return _grid(radius_h=radii, max_nn=(60,), passes=(1, 2) if quick else (1, 2, 4))


def _bilateral_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    return _grid(sigma_s_h=(1.0, 2.0) if quick else (1.0, 1.5, 2.5, 4.0),
                 sigma_r_h=(0.5, 1.0) if quick else (0.25, 0.5, 1.0, 2.0),
                 passes=(1, 3) if quick else (1, 2, 4))


# --- PyMeshLab MLS (in a child process) --------------------------------------------------------


def _ml_mls(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    """PyMeshLab's MLS projection of the points onto the MLS surface they define.

    The point set (mesh 0: the noisy points with normals -- the mesh's own, or PCA normals of
    10 neighbours for a cloud -- and per-vertex radii from 16 neighbours) and the points to
    project (mesh 1, a copy) must be two meshes: with ``controlmesh == proxymesh`` (the
    filter's default) pymeshlab 2022.2 - 2025.7 crash (SIGSEGV in
    ``GaelMls::MlsSurface::computeNeighborhood``), with or without normals and radii.
    """
    X = P
    for _ in range(s.get("passes", 1)):
        X = _ml_mls_pass(X, shape, s)
    return X


def _ml_mls_pass(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    if shape.faces is not None:
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=P, face_matrix=shape.faces.astype(np.int32)))
    else:
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=P))
        ms.compute_normal_for_point_clouds(k=10)
    ms.compute_custom_radius_scalar_attribute_per_vertex(nbneighbors=16)
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=P.copy()))
    ms.set_current_mesh(0)
    common = {"controlmesh": 0, "proxymesh": 1, "filterscale": s["filterscale"]}
    if s["method"] == "apss":
        ms.compute_mls_projection_apss(**common, sphericalparameter=s["spherical"])
    else:
        ms.compute_mls_projection_rimls(**common, sigman=s["sigman"])
    out = np.asarray(ms.mesh(1).vertex_matrix(), dtype=np.float64)
    if out.shape != P.shape:
        raise RuntimeError(f"PyMeshLab changed the vertex count ({P.shape} -> {out.shape})")
    return out


def _apss_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    return _grid(method=("apss",), filterscale=(2, 4) if quick else (2, 3, 4, 6, 8),
                 spherical=(1.0,) if quick else (0.0, 0.5, 1.0), passes=(1,) if quick else (1, 3))


def _rimls_grid(shape: Shape, quick: bool) -> list[dict[str, Any]]:
    # smaller than APSS's: RIMLS is the slower filter and the weaker peer here
    return _grid(method=("rimls",), filterscale=(2, 4) if quick else (2, 4, 8),
                 sigman=(0.75,) if quick else (0.75, 1.5), passes=(1,) if quick else (1, 3))


def _child(conn: Any, run: Run, P: FloatArray, shape: Shape, s: dict[str, Any]) -> None:
    try:
        conn.send(("ok", run(P, shape, s)))
    except Exception as exc:  # reported to the parent
        conn.send(("error", f"{type(exc).__name__}: {exc}"))


def run_isolated(run: Run, P: FloatArray, shape: Shape, s: dict[str, Any],
                 timeout: float = 600.0) -> FloatArray:
    """``run(P, shape, s)`` in a forked child; raises ``RuntimeError`` if it crashes."""
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, run, P, shape, s))
    proc.start()
    child.close()
    got = parent.recv() if parent.poll(timeout) else None
    proc.join(5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    if got is None:
        raise RuntimeError(f"crashed (exit status {proc.exitcode})")
    if got[0] != "ok":
        raise RuntimeError(got[1])
    return np.asarray(got[1], dtype=np.float64)


# --- the list ----------------------------------------------------------------------------------

_MP = mesh_peers.PEERS
_by_name = {p.name: p for p in _MP}


def _legacy(name: str, package: str) -> QualityPeer:
    p = _by_name[name]
    return QualityPeer(name, package, ("mesh",), _mesh(p.run),
                       lambda shape, quick, p=p: p.grid(quick or shape.n > 20000))


QUALITY_PEERS: list[QualityPeer] = [
    *(_legacy(p.name, p.package) for p in _MP),
    QualityPeer("PyVista windowed-sinc", "pyvista", ("mesh", "curve"), _pv_sinc, _sinc_grid,
                revision=1),
    QualityPeer("PyVista Laplacian", "pyvista", ("mesh", "curve"), _pv_laplacian, _pv_lap_grid),
    QualityPeer("Open3D cloud Laplacian", "open3d", ("cloud",), _o3d_pc_laplacian, _knn_lap_grid),
    QualityPeer("Open3D cloud Taubin", "open3d", ("cloud",), _o3d_pc_taubin, _knn_taubin_grid),
    QualityPeer("Open3D cloud MLS", "open3d", ("cloud",), _o3d_pc_mls, _mls_grid),
    QualityPeer("Open3D cloud bilateral", "open3d", ("cloud",), _o3d_pc_bilateral,
                _bilateral_grid),
    QualityPeer("PyMeshLab APSS", "pymeshlab", ("mesh", "cloud"), _ml_mls, _apss_grid, True, 1),
    QualityPeer("PyMeshLab RIMLS", "pymeshlab", ("mesh", "cloud"), _ml_mls, _rimls_grid, True, 2),
]


def peer_versions() -> dict[str, str | None]:
    """Installed version of every peer package (``None`` when it does not import)."""
    out: dict[str, str | None] = {}
    for pkg in sorted({p.package for p in QUALITY_PEERS}):
        try:
            __import__(pkg)
            out[pkg] = importlib.metadata.version(pkg)
        except Exception:  # ImportError or a missing system library
            out[pkg] = None
    return out
