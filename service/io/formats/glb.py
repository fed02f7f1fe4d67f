"""glTF binary (GLB) via trimesh: meshes and point primitives of the scene, in world coordinates.

Reading
-------
``trimesh.load(..., file_type="glb", process=False)``: every geometry of the scene (its first
instance in the scene graph) is placed in world coordinates with its node transform and
concatenated; triangles are the mesh faces. glTF splits vertices at UV and normal seams, so the
format welds by default. Texture coordinates and vertex colours are attributes (``uv``,
``color``); materials, textures, the scene graph and everything else stay in the trimesh scene
(the layout).

Writing
-------
A document read from GLB is written as its scene with new vertex positions (mapped back through
each node's inverse transform; other instances of a shared geometry move with it); trimesh
recomputes the normals it exports. Other documents become one mesh (or point cloud) with
``red green blue [alpha]`` attributes as vertex colours; an OBJ mesh's texture coordinates
(``f v/vt``) become ``TEXCOORD_0``, its vertices split where a vertex has several UVs
(:mod:`service.io._shared.texture`; spot.obj: 2930 vertices, 3225 in the glTF). glTF positions
are float32, so that mesh is stored about the centre of its bounding box, which becomes its
node's translation (a double in the glTF JSON): georeferenced coordinates (5.6e6 m) keep
float32's resolution of the extent (~6e-8 of it) instead of moving by up to 0.25 m.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.coords import as_xyz
from service.io._shared.plain import PlainDocument
from service.io._shared.texture import corner_uvs, split_at_seams
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError, MissingDependency
from service.io.source import Source

__all__ = ["GlbLayout", "read_glb", "write_glb"]


@dataclass(frozen=True, eq=False)
class GlbLayout:
    """The trimesh scene and, per geometry used, its name, transform and vertex range."""

    scene: Any
    parts: list[tuple[str, NDArray[np.float64], int, int]]


def _load(data: bytes) -> Any:
    import trimesh

    if data[:4] != b"glTF":
        raise FormatError("not a GLB file (no 'glTF' magic)", fmt="glb")
    try:
        return trimesh.load(io.BytesIO(data), file_type="glb", process=False, force="scene")
    except ImportError as exc:  # the server's installation, not the file (issue 41)
        raise MissingDependency.of(exc, "glb") from exc
    except Exception as exc:  # trimesh raises many kinds on bad input; report one line
        text = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise FormatError(f"GLB: {text}", fmt="glb") from None


def read_glb(source: Source, *, weld: bool = True) -> GeometryDocument:
    """Read a GLB file (see the module docstring)."""
    import trimesh

    scene = _load(source.data())
    parts: list[tuple[str, NDArray[np.float64], int, int]] = []
    pts, faces, uv, color = [], [], [], []
    at = 0
    seen: set[str] = set()
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geom = scene.geometry.get(name)
        if name in seen or not isinstance(geom, trimesh.Trimesh | trimesh.PointCloud):
            continue
        seen.add(name)
        v = np.asarray(geom.vertices, dtype=np.float64)
        world = v @ transform[:3, :3].T + transform[:3, 3]
        pts.append(world)
        if isinstance(geom, trimesh.Trimesh) and len(geom.faces):
            faces.append(np.asarray(geom.faces, dtype=np.int64) + at)
        visual = getattr(geom, "visual", None)
        uv.append(getattr(visual, "uv", None))
        kind = getattr(visual, "kind", None)
        colors = getattr(visual, "vertex_colors", None) if kind == "vertex" else None
        color.append(np.asarray(colors) if colors is not None else None)
        parts.append((name, np.asarray(transform, dtype=np.float64), at, at + len(v)))
        at += len(v)
    if not pts:
        raise FormatError("the GLB scene holds no mesh or point geometry", fmt="glb")
    points = np.concatenate(pts)
    attributes: dict[str, NDArray[Any]] = {}
    if all(u is not None and len(u) == len(p) for u, p in zip(uv, pts, strict=True)):
        attributes["uv"] = np.concatenate([np.asarray(u) for u in uv])
    if all(c is not None for c in color):
        attributes["color"] = np.concatenate([np.asarray(c) for c in color])
    flat = np.concatenate(faces) if faces else None
    polygons = (flat.reshape(-1), np.full(len(flat), 3)) if flat is not None else None
    doc = assemble(points, fmt="glb", polygons=polygons, weld=weld)
    return doc.with_extras(
        attributes=attributes, precision=Precision("float32"), layout=GlbLayout(scene, parts)
    )


def _bytes(colors: NDArray[Any]) -> NDArray[np.uint8]:
    """Colour channels as bytes (trimesh reads float channels as 0..1): 16-bit values scaled,
    floats within [0, 1] taken as fractions, others as 0..255."""
    v = colors.astype(np.float64)
    top = float(v.max()) if v.size else 0.0
    if top > 255:
        v *= 255.0 / 65535.0
    elif colors.dtype.kind == "f" and top <= 1.0:
        v *= 255.0
    return np.clip(np.rint(v), 0, 255).astype(np.uint8)


def _export(scene: Any) -> bytes:
    try:
        data = scene.export(file_type="glb")
    except ImportError as exc:  # the server's installation, not the file (issue 41)
        raise MissingDependency.of(exc, "glb") from exc
    except Exception as exc:
        text = " ".join(str(exc).split())[:200]
        raise FormatError(f"GLB export failed: {text}", fmt="glb") from None
    return bytes(data)


def write_glb(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as GLB (see the module docstring)."""
    import trimesh

    pts = as_xyz(plain.points, "glb")
    layout = plain.layout
    if isinstance(layout, GlbLayout) and layout.parts[-1][3] == plain.n:
        scene = layout.scene.copy()
        if plain.moved:
            for name, transform, a, b in layout.parts:
                inv = np.linalg.inv(transform)
                local = pts[a:b] @ inv[:3, :3].T + inv[:3, 3]
                scene.geometry[name].vertices = local.astype(plain.coordinate_dtype())
        out.write(_export(scene))
        return
    colors = None
    attrs = plain.attributes
    if all(c in attrs for c in ("red", "green", "blue")):
        channels = [attrs[c] for c in ("red", "green", "blue", "alpha") if c in attrs]
        colors = _bytes(np.column_stack(channels))
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2 if plain.n else np.zeros(3)
    local = pts - centre
    uvs = corner_uvs(plain, "glb")
    if uvs is not None:  # OBJ texture coordinates: one vertex per (vertex, vt) pair
        vertex_of, vt_of, faces = split_at_seams(np.asarray(plain.faces), uvs[0])
        visual = trimesh.visual.TextureVisuals(uv=uvs[1][vt_of])
        geom: Any = trimesh.Trimesh(local[vertex_of], faces, visual=visual, process=False)
    elif plain.faces is not None and len(plain.faces):
        geom = trimesh.Trimesh(local, plain.faces, vertex_colors=colors, process=False)
    else:
        geom = trimesh.PointCloud(local, colors=colors)
    placed = np.eye(4)
    placed[:3, 3] = centre
    scene = trimesh.Scene()
    scene.add_geometry(geom, transform=placed)
    out.write(_export(scene))
