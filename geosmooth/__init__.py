"""geosmooth as a library: smoothing with a deviation budget tau (KU Leuven report TW 451).

::

    import geosmooth

    smoothed = geosmooth.smooth(points, tau=0.5)                 # (n, s) array -> array
    mesh2 = geosmooth.smooth(trimesh_mesh, rms=1e-4)             # trimesh in, trimesh out
    cloud2, result = geosmooth.smooth(o3d_cloud, tau=2e-4, full_output=True)
    geosmooth.describe(points)["suggested_tau"]                   # noise estimate, tau range
    doc = geosmooth.read("bunny.ply")
    geosmooth.write(geosmooth.smooth(doc, tau=2e-4), "bunny-smooth.ply")
    geosmooth.smooth_file("scan.laz", "scan-smooth.laz", rms=0.01, tile_points=2_000_000)

:func:`smooth` accepts numpy arrays (with ``faces=`` / ``edges=``), :class:`Geometry`,
documents from :func:`read`, ``trimesh.Trimesh`` / ``PointCloud`` / ``Path3D`` and Open3D
``TriangleMesh`` / ``PointCloud`` / ``LineSet``, and returns the same kind of object with the
input's vertex count, order and connectivity. Parameters are those of
:class:`SmoothingParams`, the one definition the CLI and the HTTP API share. The engine itself
is :mod:`service.core`, entered through the use cases of :mod:`service.workflows`; this package
only adapts objects and files to them.
"""

from __future__ import annotations

import os
from typing import Any

from geosmooth._convert import adapt
from service.core import (
    Geometry,
    GeometryError,
    GeosmoothError,
    ParameterError,
    ProgressEvent,
    SmoothingParams,
    SmoothResult,
    SolverError,
    TauOutOfRange,
)
from service.io import FormatError, GeometryDocument, UnsupportedFormat

__all__ = [
    "FormatError",
    "Geometry",
    "GeometryDocument",
    "GeometryError",
    "GeosmoothError",
    "ParameterError",
    "ProgressEvent",
    "SmoothResult",
    "SmoothingParams",
    "SolverError",
    "TauOutOfRange",
    "UnsupportedFormat",
    "describe",
    "read",
    "smooth",
    "smooth_file",
    "write",
]


def _params(params: SmoothingParams | dict[str, Any] | None, values: dict[str, Any]) -> Any:
    """One :class:`SmoothingParams` from a model or mapping plus keyword values."""
    if isinstance(params, SmoothingParams):
        base = params.model_dump(exclude_unset=True)
    else:
        base = dict(params or {})
    return SmoothingParams.model_validate({**base, **values})


def smooth(
    geometry: Any,
    params: SmoothingParams | dict[str, Any] | None = None,
    *,
    faces: Any = None,
    edges: Any = None,
    progress: Any = None,
    full_output: bool = False,
    **values: Any,
) -> Any:
    """Smooth points, curves or meshes; returns the same kind of object.

    Parameters
    ----------
    geometry : array_like, Geometry, GeometryDocument, trimesh or Open3D object
        An ``(n, s)`` array of points (any dimension; ``faces`` (m, 3) or ``edges`` (k, 2)
        make it a mesh or a curve network, else it is a point cloud), or an object named above.
    params : SmoothingParams or dict, optional
        Parameters; keyword ``values`` (``tau=0.5``, ``laplacian="feature"``) are added.
    progress : callable, optional
        ``progress(event)`` with a :class:`ProgressEvent` per stage and per lambda tried.
    full_output : bool
        Return ``(smoothed, result)``, ``result`` being the :class:`SmoothResult` (lambda, phi,
        tau, history, deviations, timings, ``result.report()``).

    Raises
    ------
    pydantic.ValidationError
        Invalid parameters.
    GeosmoothError
        Invalid geometry, parameters this geometry cannot take (e.g. tau outside
        ``(0, phi(0))``: :class:`TauOutOfRange` carries the range), solver failure.
    """
    from service.core.linalg.threads import use_default_threads
    from service.workflows.smooth_file import counted, run_engine

    use_default_threads(os.environ)  # GEOSMOOTH_THREADS, default 1 (docs/threads.md)
    doc, rebuild = adapt(geometry, faces=faces, edges=edges)
    result = counted(run_engine(doc.geometry, _params(params, values), progress), doc)
    smoothed = rebuild(result.points)
    return (smoothed, result) if full_output else smoothed


def smooth_file(
    source: str | os.PathLike[str],
    target: str | os.PathLike[str],
    params: SmoothingParams | dict[str, Any] | None = None,
    *,
    fmt: str | None = None,
    output_format: str | None = None,
    progress: Any = None,
    **values: Any,
) -> SmoothResult:
    """Read a file, smooth it, write the result to ``target`` atomically: the use case of
    ``geosmooth smooth`` (:func:`service.workflows.smooth_file.smooth_file`).

    With ``tile_points`` a LAS/LAZ, binary PLY or XYZ file written in its own format is
    streamed (only its coordinates are held). ``fmt`` / ``output_format`` default to the
    extensions; parameters as in :func:`smooth`. Returns the :class:`SmoothResult`.
    """
    from pathlib import Path

    from service.core.linalg.threads import use_default_threads
    from service.io import detect_format
    from service.workflows.smooth_file import smooth_file as run

    use_default_threads(os.environ)
    out = output_format or detect_format(os.fspath(target))
    done = run(Path(source), Path(target), _params(params, values), fmt=fmt, out_fmt=out,
               progress=progress)  # fmt: skip
    return done.result


def describe(
    geometry: Any,
    params: SmoothingParams | dict[str, Any] | None = None,
    *,
    faces: Any = None,
    edges: Any = None,
    **values: Any,
) -> dict[str, Any]:
    """What ``geometry`` is and which budgets it admits, without smoothing it.

    Takes what :func:`smooth` takes and returns :func:`service.core.info.describe`'s dict
    (``n_points``, ``kind``, ``phi0``, ``tau_range``, ``rms_range``, ``sigma_estimate``,
    ``suggested_tau``, ...: the body of ``POST /v1/info`` and ``geosmooth info``).
    """
    from service.core.info import describe as describe_geometry

    doc, _ = adapt(geometry, faces=faces, edges=edges)
    return describe_geometry(doc.geometry, _params(params, values))


def read(
    path: str | os.PathLike[str] | bytes, fmt: str | None = None, **options: Any
) -> GeometryDocument:
    """Read a geometry file (format from ``fmt``, the extension or the content).

    ``options`` are those of :func:`service.io.read_geometry` (``weld=True``, ``xyz_dims=``).
    """
    from service.io import read_geometry

    return read_geometry(path, fmt, **options)


def write(
    geometry: Any,
    path: str | os.PathLike[str],
    fmt: str | None = None,
    **options: Any,
) -> None:
    """Write any object :func:`smooth` accepts to a file, atomically.

    The format comes from ``fmt`` or the file name's extension; ``options`` are those of
    :func:`service.io.write_geometry` (e.g. ``ply_ascii=True``). A document from :func:`read`
    is written back with everything the file held (comments, welded vertices, polylines).
    """
    from service.io import detect_format
    from service.workflows.smooth_file import write_document

    doc, _ = adapt(geometry)
    write_document(doc, os.fspath(path), fmt or detect_format(os.fspath(path)), **options)

