"""An extreme-input corpus, generated at test time (small, deterministic): numbers at the
edges of floating point, tiny and degenerate inputs, a few malformed bodies the io helper's
file corpus (``tests/corpus``, run by ``test_api_corpus.py`` too) does not have.

Each entry is ``(name, filename, bytes, expected)`` where ``expected`` is the set of statuses
an endpoint may answer: ``ok`` (smoothed), ``400`` (malformed file), ``413``, ``415``, ``422``
(geometry or parameters that cannot be smoothed). Whatever the answer, it is never a 5xx and
never contains NaN or infinity.
"""

from __future__ import annotations

import json

import numpy as np

from tests.api.api_helpers import icosphere, noisy_plane_cloud, obj_bytes, ply_bytes, xyz_bytes

OK, BAD = frozenset({"ok"}), frozenset({"400"})
ANY_4XX = frozenset({"400", "413", "415", "422"})
OK_OR_422 = frozenset({"ok", "422"})


def _binary_ply(points: np.ndarray, count: int | None = None, tail: bytes = b"") -> bytes:
    head = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(points) if count is None else count}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()
    return head + np.asarray(points, "<f4").tobytes() + tail


def _json(obj: object) -> bytes:
    return json.dumps(obj).encode()


def corpus() -> list[tuple[str, str, bytes, frozenset[str]]]:
    """The corpus entries (see the module docstring)."""
    rng = np.random.default_rng(15)
    sphere, faces = icosphere(1)
    cloud = noisy_plane_cloud(80, seed=3)
    tiny = [rng.normal(size=(k, 3)) for k in range(1, 9)]
    out: list[tuple[str, str, bytes, frozenset[str]]] = [
        # --- malformed files beyond the io corpus's (tests/corpus): protocol-level oddities
        ("empty", "e.xyz", b"", BAD),
        ("ply-vertex-count-1e9", "c.ply", _binary_ply(sphere[:3], count=10**9), BAD | {"413"}),
        ("json-nested", "n.json", b"[" * 50_000 + b"]" * 50_000, BAD),
        ("json-huge-int", "i.json", b'{"points": [[' + b"9" * 5000 + b", 0, 0]]}", BAD | {"422"}),
        (
            "random-bytes-noext",
            "blob",
            bytes(rng.integers(0, 256, 3000, dtype=np.uint8)),
            BAD | {"415"},
        ),
        # --- unsupported formats: 415
        ("vtk-file", "m.vtp", b"<?xml version='1.0'?><VTKFile/>", frozenset({"415"})),
        ("svg-noext", "drawing", b"<svg xmlns='http://www.w3.org/2000/svg'/>", frozenset({"415"})),
        # --- numbers: a result (finite) or 422
        ("nan-coordinate", "n.xyz", b"0 0 0\nnan 1 0\n0 1 1\n1 1 1\n", frozenset({"400", "422"})),
        (
            "inf-coordinate",
            "i.obj",
            b"v 1e999 0 0\nv 0 0 0\nv 1 1 1\nf 1 2 3\n",
            frozenset({"400", "422"}),
        ),
        ("coordinates-1e300", "big.xyz", xyz_bytes(cloud * 1e300), OK_OR_422),
        ("coordinates-1e-300", "small.xyz", xyz_bytes(cloud * 1e-300), OK_OR_422),
        ("georeferenced", "geo.xyz", xyz_bytes(cloud + np.array([6.6e5, 5.6e6, 120.0])), OK),
        (
            "weights-1e200",
            "w.json",
            _json({"points": cloud.tolist(), "weights": [1e200] * 80}),
            OK_OR_422,
        ),
        (
            "weights-zero",
            "z.json",
            _json({"points": cloud.tolist(), "weights": [0.0] * 80}),
            BAD | {"422"},
        ),
        ("duplicate-points", "d.xyz", xyz_bytes(np.repeat(cloud[:20], 4, axis=0)), OK_OR_422),
        ("all-equal-points", "a.xyz", xyz_bytes(np.zeros((30, 3))), OK_OR_422),
        # --- tiny and degenerate inputs: a result or a clear 422
        ("single-triangle", "t.obj", obj_bytes(sphere[:3], np.array([[0, 1, 2]])), OK_OR_422),
        (
            "colinear-mesh",
            "c.obj",
            obj_bytes(np.outer(np.arange(4.0), [1, 1, 1]), np.array([[0, 1, 2], [1, 2, 3]])),
            OK_OR_422,
        ),
        (
            "degenerate-faces",
            "g.obj",
            obj_bytes(sphere[:4], np.array([[0, 0, 1], [1, 2, 3]])),
            OK_OR_422 | BAD,
        ),
        (
            "one-dimensional",
            "1d.xyz",
            b"\n".join(str(v).encode() for v in rng.normal(size=40)) + b"\n",
            OK_OR_422 | BAD,
        ),
        ("high-dimensional", "hd.xyz", xyz_bytes(rng.normal(size=(200, 12))), OK_OR_422),
        *[(f"tiny-cloud-{len(t)}", f"tiny{len(t)}.xyz", xyz_bytes(t), OK_OR_422) for t in tiny],
        # --- a sane control
        ("control-mesh", "s.ply", ply_bytes(sphere, faces), OK),
        ("control-binary", "b.ply", _binary_ply(sphere), OK),
    ]
    return out
