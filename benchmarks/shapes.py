"""Test inputs: noisy synthetic shapes with known ground truth, and real meshes from shared data.

Every generator is deterministic (fixed seeds). Real files are only read from the shared data
directory (see :func:`data_dir` and its ``MANIFEST.md``); nothing is copied into the repository.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from benchmarks import metrics

__all__ = [
    "SOLVER_SIZES",
    "Case",
    "box_mesh",
    "data_dir",
    "load_mesh",
    "noisy_circle",
    "noisy_cloud",
    "peer_cases",
    "solver_case",
    "sphere_mesh",
    "torus_mesh",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass
class Case:
    """One benchmark input.

    Attributes
    ----------
    name : str
        Short label used in tables.
    points : ndarray, shape (n, s)
        Noisy input ``P``.
    faces, edges : ndarray or None
        Connectivity (mesh triangles or polyline edges); both ``None`` for a point cloud.
    source : str
        Where the data comes from and what noise was added.
    sigma : float or None
        Standard deviation of the isotropic Gaussian noise added per coordinate; ``None`` for
        real (unknown) noise.
    tau_noise : float
        Noise energy: ``n * s * sigma^2`` for added noise, an estimate for real noise.
    truth : callable or None
        ``truth(X)`` gives the unsigned distance of each row of ``X`` to the ground-truth
        surface or curve.
    closed : bool
        Closed triangle mesh (3D) or closed polygon (2D): volume / area change is meaningful.
    """

    name: str
    points: FloatArray
    faces: IntArray | None = None
    edges: IntArray | None = None
    source: str = ""
    sigma: float | None = None
    tau_noise: float = 0.0
    truth: Callable[[FloatArray], FloatArray] | None = None
    closed: bool = False
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.points.shape[0])

    @property
    def kind(self) -> str:
        if self.faces is not None:
            return "mesh"
        return "curve" if self.edges is not None else "cloud"


def data_dir() -> Path:
    """Directory of the shared real data.

    ``GEOSMOOTH_SHARED_DATA`` if set (as for the tests), else ``shared/data`` beside the
    repository, else beside the directory that holds it (a git worktree one level down).
    """
    env = os.environ.get("GEOSMOOTH_SHARED_DATA")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[1]
    beside = repo.parent / "shared" / "data"
    return beside if beside.is_dir() else repo.parent.parent / "shared" / "data"


def load_mesh(name: str, weld: bool = False) -> tuple[FloatArray, IntArray]:
    """Vertices and triangles of a real mesh, unreferenced vertices removed.

    Parameters
    ----------
    name : str
        File name inside :func:`data_dir`.
    weld : bool
        Merge vertices split only by texture coordinates or normals (e.g. ``spot.obj``).
    """
    import trimesh

    path = data_dir() / name
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} not found (set GEOSMOOTH_SHARED_DATA to the data directory)"
        )
    mesh = trimesh.load(path, process=False)
    if isinstance(mesh, trimesh.Scene):  # an OBJ with materials loads as a scene
        mesh = trimesh.util.concatenate(list(mesh.geometry.values()))
    if weld:
        mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.remove_unreferenced_vertices()
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def mean_edge_length(points: FloatArray, faces: IntArray) -> float:
    """Mean length of the (directed) triangle edges."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return float(np.linalg.norm(points[e[:, 0]] - points[e[:, 1]], axis=1).mean())


def _noise(shape: tuple[int, ...], sigma: float, seed: int) -> FloatArray:
    return np.random.default_rng(seed).normal(0.0, sigma, size=shape)


def torus_grid(nu: int, nv: int, R: float = 1.0, r: float = 0.4) -> tuple[FloatArray, IntArray]:
    """Clean torus, ``nu`` segments around the big circle and ``nv`` around the tube."""
    u = np.linspace(0.0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0.0, 2 * np.pi, nv, endpoint=False)
    U, V = np.meshgrid(u, v, indexing="ij")
    P = np.stack(
        [(R + r * np.cos(V)) * np.cos(U), (R + r * np.cos(V)) * np.sin(U), r * np.sin(V)], -1
    ).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    F = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return P, F.astype(np.int64)


def torus_mesh(nu: int, nv: int, rel_sigma: float = 0.25, seed: int = 1) -> Case:
    """Noisy torus (R = 1, r = 0.4); noise sigma = ``rel_sigma`` x mean edge length."""
    P, F = torus_grid(nu, nv)
    sigma = rel_sigma * mean_edge_length(P, F)
    return Case(
        name=f"torus {P.shape[0] // 1000}K",
        points=P + _noise(P.shape, sigma, seed),
        faces=F,
        source=f"synthetic torus {nu}x{nv} (R=1, r=0.4), Gaussian noise sigma={sigma:.3g}",
        sigma=sigma,
        tau_noise=P.size * sigma**2,
        truth=lambda X: metrics.torus_distance(X, 1.0, 0.4),
        closed=True,
    )


def sphere_mesh(subdivisions: int = 4, sigma: float = 0.02, seed: int = 2) -> Case:
    """Noisy unit icosphere."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    P = np.asarray(s.vertices, dtype=np.float64)
    return Case(
        name="sphere",
        points=P + _noise(P.shape, sigma, seed),
        faces=np.asarray(s.faces, dtype=np.int64),
        source=f"icosphere({subdivisions}), r=1, Gaussian noise sigma={sigma}",
        sigma=sigma,
        tau_noise=P.size * sigma**2,
        truth=metrics.sphere_distance,
        closed=True,
    )


def box_mesh(subdivisions: int = 5, sigma: float = 0.02, seed: int = 3) -> Case:
    """Noisy 2 x 2 x 2 box (sharp edges and corners), midpoint-subdivided."""
    import trimesh

    b = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    for _ in range(subdivisions):
        b = b.subdivide()
    P = np.asarray(b.vertices, dtype=np.float64)
    return Case(
        name="box",
        points=P + _noise(P.shape, sigma, seed),
        faces=np.asarray(b.faces, dtype=np.int64),
        source=f"box 2x2x2 subdivided {subdivisions}x, Gaussian noise sigma={sigma}",
        sigma=sigma,
        tau_noise=P.size * sigma**2,
        truth=lambda X: metrics.box_distance(X, 1.0),
        closed=True,
    )


def noisy_circle(n: int = 400, sigma: float = 0.02, seed: int = 4) -> Case:
    """Closed 2D polygon on the unit circle, sampled non-uniformly (spacing ratio ~9)."""
    u = np.arange(n) / n
    t = 2 * np.pi * u + 0.8 * np.sin(2 * np.pi * u)
    P = np.stack([np.cos(t), np.sin(t)], -1)
    idx = np.arange(n)
    return Case(
        name="circle (2D polyline)",
        points=P + _noise(P.shape, sigma, seed),
        edges=np.stack([idx, (idx + 1) % n], -1).astype(np.int64),
        source=f"unit circle, {n} points, non-uniform spacing, Gaussian noise sigma={sigma}",
        sigma=sigma,
        tau_noise=P.size * sigma**2,
        truth=metrics.sphere_distance,
        closed=True,
    )


def noisy_cloud(n: int = 5000, sigma: float = 0.02, seed: int = 5) -> Case:
    """Point cloud: uniform random points on the unit sphere plus noise."""
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    return Case(
        name="sphere point cloud",
        points=P + rng.normal(0.0, sigma, size=P.shape),
        source=f"{n} random points on the unit sphere, Gaussian noise sigma={sigma}",
        sigma=sigma,
        tau_noise=P.size * sigma**2,
        truth=metrics.sphere_distance,
    )


def real_scan() -> Case:
    """One raw range scan (bun000, triangulated) against the merged bunny as reference."""
    P, F = load_mesh("bun000_rangegrid_tri.ply")
    R, RF = load_mesh("bun_zipper.ply")
    ref = metrics.SurfaceDistance(R, RF)
    d = ref(P)
    return Case(
        name="bun000 scan",
        points=P,
        faces=F,
        source=(
            "bun000_rangegrid_tri.ply (real Cyberware range scan, unreferenced vertices dropped), "
            "reference surface bun_zipper.ply (Stanford; not independent ground truth)"
        ),
        sigma=None,
        tau_noise=float(np.sum(d**2)),
        truth=ref,
        closed=False,
    )


def peer_cases(quick: bool = False) -> list[Case]:
    """Inputs of the peer comparison (the scan only without ``quick``)."""
    cases = [sphere_mesh(), torus_mesh(120, 48), box_mesh(), noisy_circle(), noisy_cloud()]
    if not quick:
        cases.append(real_scan())
    return cases


# ---------------------------------------------------------------------------------------------
# solver-table inputs (report fig. 8 sizes)

SOLVER_SIZES: dict[str, str] = {
    "1K": "synthetic noisy torus 50x20 (1,000 vertices; for smoke tests)",
    "3K": "spot.obj (2,930 vertices after welding UV seams; clean, noise added)",
    "40K": "bun000_rangegrid_tri.ply (39,977 vertices; real scanner noise)",
    "44K": "horse.ply (48,485 vertices; clean, noise added)",
    "56K": "synthetic noisy torus 350x160 (56,000 vertices)",
    "122K": "synthetic noisy torus 550x222 (122,100 vertices)",
    "500K": "synthetic noisy torus 1120x446 (499,520 vertices)",
}


def _noisy_real(name: str, weld: bool, label: str, seed: int) -> Case:
    P, F = load_mesh(name, weld=weld)
    sigma = 0.25 * mean_edge_length(P, F)
    return Case(
        name=label,
        points=P + _noise(P.shape, sigma, seed),
        faces=F,
        source=f"{name}, Gaussian noise sigma = 0.25 x mean edge = {sigma:.3g}",
        sigma=sigma,
        tau_noise=P.size * sigma**2,
    )


def solver_case(size: str) -> Case:
    """The mesh for one row of the solver table (keys of :data:`SOLVER_SIZES`)."""
    if size == "3K":
        return _noisy_real("spot.obj", True, "spot", 11)
    if size == "40K":
        c = real_scan()
        c.truth = None
        return c
    if size == "44K":
        return _noisy_real("horse.ply", False, "horse", 12)
    grids = {"1K": (50, 20), "56K": (350, 160), "122K": (550, 222), "500K": (1120, 446)}
    if size in grids:
        return torus_mesh(*grids[size], seed=13)
    raise KeyError(f"unknown size {size!r}; choose from {', '.join(SOLVER_SIZES)}")
