"""Issue 41 item 5: the PDAL ``filters.python`` recipe (docs/recipes/pdal_geosmooth.py) called
as PDAL calls it (dimension arrays in, ``outs`` filled, ``pdalargs`` a module global) gives the
points ``geosmooth smooth --where`` gives, and keeps the unselected points bit-identical."""

from __future__ import annotations

import importlib.util
from types import ModuleType

import numpy as np

from tests.cli.conftest import REPO


def _recipe() -> ModuleType:
    path = REPO / "docs" / "recipes" / "pdal_geosmooth.py"
    spec = importlib.util.spec_from_file_location("pdal_geosmooth", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_pdal_recipe_smooths_the_selection_as_the_library_does() -> None:
    import geosmooth

    rng = np.random.default_rng(5)
    n = 2000
    x, y = rng.random(n) * 40, rng.random(n) * 40
    ins = {
        "X": x, "Y": y, "Z": np.sin(x / 6) + rng.normal(0, 0.02, n),
        "Classification": np.where(rng.random(n) < 0.7, 2, 6).astype(np.uint8),
    }  # fmt: skip
    recipe = _recipe()
    recipe.pdalargs = {"rms": 0.015, "where": "Classification == 2"}
    outs: dict[str, np.ndarray] = {}
    assert recipe.smooth(ins, outs) is True
    ground = ins["Classification"] == 2
    xyz = np.column_stack([ins["X"], ins["Y"], ins["Z"]])
    expected = geosmooth.smooth(
        geosmooth.Geometry(xyz, fixed=np.flatnonzero(~ground)), {"rms": 0.015}
    ).points
    got = np.column_stack([outs["X"], outs["Y"], outs["Z"]])
    assert np.array_equal(got, expected)
    assert np.array_equal(got[~ground], xyz[~ground])
    moved = np.linalg.norm(got[ground] - xyz[ground], axis=1)
    assert np.sqrt(np.mean(moved**2) * ground.sum() / n) > 0.005  # the budget was spent
