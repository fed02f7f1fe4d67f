"""Imported once by the process that forks job processes (the embedded queue's forkserver, an RQ
worker), *for its side effect*: load the engine and run one tiny smoothing, so that what the
engine initialises lazily on first use (numba-compiled kernels, solver and format modules,
caches) is inherited by every job process instead of being redone in each.

It also loads what a job would otherwise load under its address-space cap (numba/llvmlite for
the symbolic factor count, the GCV path): a library mapped inside the cap took its share of a
small job's budget, and one that could not be mapped failed the job (see limits.memory_cap_hit).

Measured on the 2-core dev box: a tiny job's run in a fresh fork of a process that only imported
the engine took 150-370 ms, of which ~60 ms were threadpoolctl's library scan and most of the
rest first-use initialisation; see service/jobs/README.md.
"""

from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp

from service.core.geometry import Geometry
from service.core.linalg.resources import factor_size
from service.core.linalg.threads import limit_threads
from service.core.params import SmoothingParams
from service.core.pipeline import smooth_one as smooth
from service.io import GeometryDocument, read_geometry, write_geometry

__all__ = ["apply_thread_limit", "warm_compiled", "warm_up"]


def warm_up() -> None:
    """Smooth a 16-point ring once (tau search included) and write and read it back; smooth
    a tiny mesh and a tiny cloud (the compiled neighbourhood kernels)."""
    n = 16
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    rng = np.random.default_rng(0)
    ring = Geometry(np.c_[np.cos(t), np.sin(t), np.zeros(n)] + rng.normal(0, 0.01, (n, 3)),
                    edges=np.c_[np.arange(n), (np.arange(n) + 1) % n])  # fmt: skip
    result = smooth(ring, SmoothingParams(rms=0.005))
    # a mesh (1-rings, normal displacement) and a cloud (Delaunay fans): every compiled kernel
    # of service.core.operator.kernels is loaded here once, not in each job process
    octahedron = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    faces = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                      [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])  # fmt: skip
    mesh = Geometry(octahedron + rng.normal(0, 0.01, (6, 3)), faces=faces)
    smooth(mesh, SmoothingParams(rms=0.005))
    smooth(Geometry(rng.normal(0, 1.0, (40, 3))), SmoothingParams(rms=0.05))
    doc = GeometryDocument.from_geometry(ring)
    for fmt in ("json", "ply"):
        read_geometry(write_geometry(doc, fmt, result.points), fmt)
    gcv = ring.points[:, :2] + rng.normal(0, 0.01, (n, 2))  # the free-displacement/GCV path
    smooth(Geometry(gcv, edges=ring.edges), SmoothingParams(tau="gcv"))
    # numba (llvmlite, ~100 MB of address space) compiles the symbolic factor count of the
    # memory-aware solver choice: loaded here, before any job's RLIMIT_AS, not under it.
    pattern = sp.csr_matrix(np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1))
    factor_size(pattern, None)
    warm_compiled(rng)


def warm_compiled(rng: np.random.Generator) -> None:
    """Call the compiled kernels that only inputs of 50,000 points or more reach (the grid
    ``k``-NN, the data weights' fits and isolation pass, the closed-form frames, the per-face
    passes of the finish and the shape checks, the normal system's scaling) on a tiny
    surface: without this, the first large job or upload of each process compiled them (a few
    CPU seconds each; more than a minute on a loaded machine with no numba cache yet)."""
    from service.core.noise.fast_fits import leave_one_out, patch_variances
    from service.core.noise.fast_weights import isolation_distances, local_sigma
    from service.core.operator.knn import grid_knn
    from service.core.system.fast_frames import surface_normals

    side = 12
    u, v = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float))
    sheet = np.c_[u.ravel(), v.ravel(), rng.normal(0, 0.01, side * side)]
    _, nbr = grid_knn(sheet, 10)
    grid_knn(np.r_[sheet, [[0.0, 0.0, 50.0]]], 10)  # a point far off: the widening search
    leave_one_out(sheet, nbr, 2)
    leave_one_out(sheet, nbr, 2, np.ones((nbr.shape[0], nbr.shape[1] - 1), dtype=bool))
    quad = np.arange(side * side).reshape(side, side)[:-1, :-1].ravel()
    faces = np.r_[np.c_[quad, quad + 1, quad + side], np.c_[quad + 1, quad + side + 1, quad + side]]
    isolation_distances(Geometry(sheet), nbr)
    isolation_distances(Geometry(sheet, faces=faces), nbr)
    local_sigma(np.ones(side * side), nbr, 4)
    patch_variances(sheet, nbr)
    normals = surface_normals(sheet, 10)[:, :, 0]
    # coincident points (issue 42 item 5): rows of the distinct points' search expanded
    from service.core.operator.knn import _collapsed, _copies

    copies = np.r_[sheet, np.repeat(sheet[:1], 40, axis=0)]
    _collapsed(_copies(copies), 10, np.arange(copies.shape[0], dtype=np.int64))
    # the neighbourhood kernels: below 50,000 points a run takes their NumPy versions
    # (operator.sized_kernels), but once this loads numba every run of the process uses these
    from service.core.operator import kernels

    kernels.mesh_rings(np.ascontiguousarray(faces, dtype=np.int64), side * side)
    kernels.has_duplicate_faces(np.ascontiguousarray(faces, dtype=np.int64), side * side)
    kernels.neighbourhood_covariances(sheet, np.ascontiguousarray(nbr, dtype=np.int64))
    kernels.polar_hull_fans(np.ascontiguousarray(sheet[nbr[:, 1:4], :2] - sheet[:, None, :2]))
    # the finish and the shape checks (issue 30): per-face passes; the normal system's scaling
    from service.core.finish import mesh_kernels
    from service.core.system.fast_frames import scale_by_normals

    faces = np.ascontiguousarray(faces, dtype=np.int64)
    mesh_kernels.folded(mesh_kernels.face_normals(sheet, faces), faces, side * side)
    mesh_kernels.signed_volumes(sheet, faces)
    A = sp.csr_matrix(sp.eye(side * side, format="csr"), copy=True)
    scale_by_normals(A.indptr, A.indices, A.data, np.ascontiguousarray(normals))


def apply_thread_limit() -> None:
    """Cap the BLAS/OpenMP pools at ``GEOSMOOTH_THREADS_PER_JOB`` (set by the pool before it
    starts the forkserver): the cap is a library global, inherited by every fork."""
    threads = os.environ.get("GEOSMOOTH_THREADS_PER_JOB")
    if threads:
        limit_threads(int(threads))


apply_thread_limit()
warm_up()
