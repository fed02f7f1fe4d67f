"""Issue 41 item 1: every format ``make run`` serves works with the base install alone.

``make run`` installs ``pip install -e .`` (no extras). Rather than building a second venv (no
network in tests), a fresh interpreter writes every output format (a textured OBJ mesh, a
cloud, a geographic track) and the test checks that every module it loaded belongs to a
distribution of the base install's closure (``Requires-Dist`` without extras, followed
recursively). Pillow was only in the dev extra; trimesh imports it for a textured GLB.

A missing package is a server fault: :class:`~service.io.errors.MissingDependency` (HTTP 500
naming the package, CLI status 1), never the user's "Malformed input file".
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

_WRITE_EVERY_FORMAT = r"""
import importlib.abc, json, sys

BLOCKED = set(json.loads(sys.argv[1]))
STARTUP = {m.split(".")[0] for m in sys.modules}  # site's .pth hooks, before any import here


class BaseInstallOnly(importlib.abc.MetaPathFinder):
    # a module of a distribution outside the base install is absent, as in that venv
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, BaseInstallOnly())
import numpy as np
from service.io import read_geometry, write_geometry
from service.io.registry import FORMATS

obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.1\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n" \
      b"f 1/1 2/2 3/3\nf 2/2 4/4 3/3\n"
mesh = read_geometry(obj, "obj")
rng = np.random.default_rng(1)
xyz = "\n".join(f"{x} {y} {z}" for x, y, z in rng.random((50, 3))).encode()
cloud = read_geometry(xyz, "xyz")
gpx = (b'<?xml version="1.0"?><gpx version="1.1" creator="t" '
       b'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>'
       + b"".join(b'<trkpt lat="50.%d" lon="4.%d"/>' % (i, i) for i in range(1, 6))
       + b"</trkseg></trk></gpx>")
track = read_geometry(gpx, "gpx")
written = {}
for name, fmt in FORMATS.items():
    kind = {"mesh": mesh, "cloud": cloud}
    doc = track if fmt.geographic_only else next(kind[k] for k in kind if k in fmt.kinds)
    written[name] = len(write_geometry(doc, name))
mods = sorted({m.split(".")[0] for m in sys.modules} - STARTUP)
print(json.dumps({"written": written, "modules": mods}))
"""


def _base_closure() -> set[str]:
    """Normalised names of the distributions ``pip install .`` (no extras) brings in: the
    checkout's pyproject.toml ``dependencies`` (not the installed metadata, which may be
    another checkout's), then each one's installed ``Requires-Dist``."""
    project = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    seen: set[str] = {"geosmooth"}
    todo = []
    for text in project["project"]["dependencies"]:
        req = Requirement(text)
        todo += [req.name, *_extra_requires(req.name, req.extras)]
    while todo:
        name = todo.pop()
        key = name.lower().replace("_", "-")
        if key in seen:
            continue
        seen.add(key)
        try:
            requires = metadata.requires(name) or []
        except metadata.PackageNotFoundError:
            continue
        for text in requires:
            req = Requirement(text)
            if req.marker is None or req.marker.evaluate({"extra": ""}):
                todo.append(req.name)
                if req.extras:  # laspy[lazrs]: the extra's own requirements
                    todo.extend(_extra_requires(req.name, req.extras))
    return seen


def _extra_requires(name: str, extras: set[str]) -> list[str]:
    out = []
    for text in metadata.requires(name) or []:
        req = Requirement(text)
        if req.marker is not None and any(req.marker.evaluate({"extra": e}) for e in extras):
            out.append(req.name)
    return out


def _outside_base() -> list[str]:
    """Top-level modules installed here by no distribution of the base install."""
    base = _base_closure()
    return sorted(
        module
        for module, dists in metadata.packages_distributions().items()
        if not {d.lower().replace("_", "-") for d in dists} & base
    )


def test_every_served_output_format_needs_only_the_base_install() -> None:
    blocked = _outside_base()
    assert {"pytest", "playwright", "open3d"} <= set(blocked) and "PIL" not in blocked
    run = subprocess.run(
        [sys.executable, "-c", _WRITE_EVERY_FORMAT, json.dumps(blocked)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    found = json.loads(run.stdout.strip().splitlines()[-1])
    from service.io.registry import FORMATS

    assert set(found["written"]) == set(FORMATS) and all(v > 0 for v in found["written"].values())
    assert "PIL" in found["modules"]  # the textured GLB needed Pillow: now a base dependency
    assert not set(found["modules"]) & set(blocked)


_WITHOUT_PIL = r"""
import sys
sys.modules["PIL"] = None  # as on a machine without Pillow
from service.io import read_geometry, write_geometry
from service.io.errors import MissingDependency
from service.api.errors import typed_problem
obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
try:
    write_geometry(read_geometry(obj, "obj"), "glb")
except MissingDependency as exc:
    p = typed_problem(exc)
    print(exc.exit_code, p.status, p.code, p.field, exc.package, p.title)
"""


def test_a_missing_server_package_is_a_server_problem_naming_it_not_a_malformed_file() -> None:
    run = subprocess.run(
        [sys.executable, "-c", _WITHOUT_PIL], capture_output=True, text=True, check=True
    )
    code, status, problem, field, package, *title = run.stdout.split()
    assert (code, status, problem, field, package) == (
        "1", "500", "missing-dependency", "None", "pillow"
    )
    assert "Malformed" not in " ".join(title)


@pytest.mark.parametrize("text", ["No module named 'PIL'", "No module named 'lzf.sub'"])
def test_missing_dependency_names_the_pip_distribution(text: str) -> None:
    from service.io.errors import MissingDependency

    exc = MissingDependency.of(ModuleNotFoundError(text), "glb")
    assert exc.package in ("pillow", "python-neo-lzf") and f"pip install {exc.package}" in str(exc)
