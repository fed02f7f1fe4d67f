"""Issue 34 item 5: a DXF SPLINE of many fit points is read in memory linear in its size.

ezdxf interpolates fit points through a dense (n+2) x (n+2) system: an 8.8 MB DXF with one
200,000-point SPLINE grew past 11.7 GB before it was killed (8,000 points: 1.5 GB, 16 s). The
reader solves the same interpolation with scipy's banded solver (:func:`service.io.formats.dxf.
_fit_spline`): the same curve, O(n) memory. Peak RSS is measured in child processes
(``resource.getrusage``).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def spline_dxf(path: Path, n: int, tangents: bool = False) -> Path:
    import ezdxf

    doc = ezdxf.new("R2010")
    t = np.linspace(0, 40 * np.pi, n)
    spline = doc.modelspace().add_spline(fit_points=np.c_[10 * t, 50 * np.sin(t), np.cos(t)])
    if tangents:
        spline.dxf.start_tangent = (1, 2, 0)
        spline.dxf.end_tangent = (0, -1, 1)
    doc.saveas(path)
    return path


_CHILD = (
    "import json, resource, sys, time\nfrom service.io import read_geometry\n"
    "t = time.perf_counter()\nn = read_geometry(sys.argv[1]).geometry.n\n"
    "rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024\n"
    "print(json.dumps({'n': n, 'rss': rss, 'seconds': time.perf_counter() - t}))\n"
)


def _peak(path: Path) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True,
                         text=True, timeout=300, cwd=ROOT, check=True)  # fmt: skip
    return json.loads(out.stdout)  # type: ignore[no-any-return]


def test_memory_grows_linearly_with_fit_points(tmp_path: Path) -> None:
    small = _peak(spline_dxf(tmp_path / "s.dxf", 1000))
    big = _peak(spline_dxf(tmp_path / "b.dxf", 8000))
    assert big["n"] > 8 * small["n"] * 0.9
    # dense: 8000 fit points took 1.4 GB more than 1000; banded: tens of MB
    assert big["rss"] - small["rss"] < 200 << 20, (small, big)


@pytest.mark.parametrize("tangents", [False, True])
def test_the_banded_curve_is_ezdxf_curve(tmp_path: Path, tangents: bool) -> None:
    import ezdxf
    from ezdxf import path as ezpath

    from service.io.formats import dxf

    doc = ezdxf.readfile(spline_dxf(tmp_path / "c.dxf", 600, tangents))
    (entity,) = doc.modelspace().query("SPLINE")
    ref = np.array([tuple(v) for v in ezpath.make_path(entity).flattening(0.01)])
    ours = np.array([tuple(v) for v in dxf._path(entity).flattening(0.01)])
    assert ours.shape == ref.shape
    assert np.abs(ours - ref).max() < 1e-9 * np.abs(ref).max()


def test_flattened_points_are_under_the_reader_limits(tmp_path: Path) -> None:
    from service.io import InputTooLarge, ReadLimits, read_geometry

    path = spline_dxf(tmp_path / "l.dxf", 600)
    with pytest.raises(InputTooLarge, match=r"flatten to more than 1000 points .* the limit"):
        read_geometry(path, limits=ReadLimits(max_points=1000))
    with pytest.raises(InputTooLarge, match=r"600 spline fit points, more than the limit of 500"):
        read_geometry(path, limits=ReadLimits(max_points=500))
    assert read_geometry(path, limits=ReadLimits(max_points=None)).geometry.n > 1000
