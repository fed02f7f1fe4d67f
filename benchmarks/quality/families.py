"""Case families and the fixed calibration / test split (issue 21, benchmark hygiene).

A *family* is a shape with a noise model (every level of it). :data:`SPLIT` below is the one
table that assigns each family to a half: ``calibration`` (defaults and constants may be chosen
on it) or ``test`` (reported, never tuned on). It is written down, not computed from a hash, so
adding a case never moves another; a family missing from it is an error
(:func:`half_of`). Each half holds every kind (mesh, grid, curve, cloud) and roughly half of
each noise model. The in-repo families of ``cases.FULL`` are in the table too.

Issue 31's families (:data:`CASES31`, run by :mod:`benchmarks.quality.issue31`) are in the same
split, one phenomenon of the issue per group, each present in both halves on different shapes
or noise: uniform Gaussian noise on CAD shapes with corners and creases, quantized coordinates,
high noise (1 and 1.5 spacings) on regular meshes, GPS-like tracks with corners and correlated
noise, clouds with stray points far off the surface, and noise-free inputs.

New shapes (:mod:`~benchmarks.quality.surfaces`, :mod:`~benchmarks.quality.knots`) and noise
models (:mod:`~benchmarks.quality.noises`) are registered here; ``cases.make_case`` builds
``"<shape>/<noise>-<level>"`` from either registry.
"""

from __future__ import annotations

from collections.abc import Callable

from benchmarks.quality import cad, knots, surfaces, tracks
from benchmarks.quality.shapes import Shape

__all__ = ["CASES", "CASES31", "KIND", "NEW_SHAPES", "PHENOMENON", "REPEATS31", "SPLIT",
           "half_cases", "half_of", "issue31_cases"]

#: The issue's new shapes (1K - 10K points each).
NEW_SHAPES: dict[str, Callable[[], Shape]] = {
    "terrain": surfaces.terrain,
    "dem": surfaces.dem,
    "hemisphere": surfaces.hemisphere,
    "saddle-irr": surfaces.saddle,
    "sphere-irr": surfaces.sphere_irregular,
    "torusknot": knots.torus_knot,
    "fig8": knots.fig8,
    "helix": knots.helix,
    "track-2d": knots.track,
    "cloud-dens-sphere": surfaces.dense_cloud_sphere,
    "cloud-dens-terrain": surfaces.dense_cloud_terrain,
    # issue 31
    "cube-6K": cad.cube,
    "bracket": cad.bracket,
    "stepblock": cad.stepblock,
    "helicoid": surfaces.helicoid,
    "track-corners-a": tracks.track_a,
    "track-corners-b": tracks.track_b,
    "track-recorded": tracks.recorded_track,
}

#: Kind of every shape in the split (``grid``: regular grid triangulations of height fields).
KIND: dict[str, str] = {
    **dict.fromkeys(("sphere-642", "sphere-2.5K", "sphere-10K", "sphere-41K", "torus-1.4K",
                     "torus-5.8K", "torus-40K", "box", "fandisk", "spot", "bunny", "horse",
                     "hemisphere", "saddle-irr", "sphere-irr", "cube-6K", "bracket", "stepblock",
                     "helicoid"), "mesh"),
    **dict.fromkeys(("terrain", "dem"), "grid"),
    **dict.fromkeys(("circle-2d", "trefoil-3d", "network-2d", "network-3d", "torusknot", "fig8",
                     "helix", "track-2d", "track-corners-a", "track-corners-b",
                     "track-recorded"), "curve"),
    **dict.fromkeys(("cloud-sphere", "cloud-torus", "cloud-fandisk", "cloud-bunny",
                     "cloud-dens-sphere", "cloud-dens-terrain"), "cloud"),
}

C, T = "calibration", "test"

#: (shape, noise model, half, levels run by the halves' tables). Levels ``()``: an in-repo family
#: (``cases.FULL`` has its levels), in the split so that nothing is tuned on its test half.
_TABLE: tuple[tuple[str, str, str, tuple[float, ...]], ...] = (
    # --- in-repo families (cases.FULL) ---------------------------------------------------------
    ("sphere-2.5K", "normal", T, ()), ("sphere-2.5K", "iso", C, ()),
    ("sphere-2.5K", "aniso", T, ()), ("sphere-2.5K", "outliers", C, ()),
    ("torus-5.8K", "normal", C, ()), ("torus-5.8K", "iso", T, ()), ("torus-5.8K", "aniso", C, ()),
    ("box", "normal", T, ()), ("box", "iso", C, ()), ("box", "aniso", T, ()),
    ("fandisk", "normal", C, ()), ("fandisk", "iso", T, ()), ("fandisk", "aniso", C, ()),
    ("fandisk", "outliers", T, ()),
    ("spot", "normal", T, ()), ("spot", "iso", C, ()), ("spot", "aniso", T, ()),
    ("circle-2d", "normal", C, ()), ("circle-2d", "iso", T, ()), ("circle-2d", "aniso", C, ()),
    ("circle-2d", "outliers", T, ()),
    ("trefoil-3d", "normal", T, ()), ("trefoil-3d", "iso", C, ()), ("trefoil-3d", "aniso", T, ()),
    ("cloud-sphere", "normal", C, ()), ("cloud-sphere", "iso", T, ()),
    ("cloud-sphere", "aniso", C, ()), ("cloud-sphere", "outliers", T, ()),
    ("sphere-642", "aniso", C, ()), ("sphere-10K", "aniso", T, ()), ("sphere-41K", "aniso", C, ()),
    ("torus-1.4K", "aniso", T, ()), ("torus-40K", "aniso", C, ()),
    ("bunny", "aniso", T, ()), ("horse", "aniso", C, ()),
    ("network-2d", "aniso", C, ()), ("network-3d", "aniso", T, ()),
    ("cloud-torus", "aniso", T, ()), ("cloud-fandisk", "aniso", C, ()),
    ("cloud-bunny", "aniso", T, ()),
    # --- issue 21: new noise models on in-repo shapes --------------------------------------------
    ("sphere-2.5K", "view", C, (0.5,)), ("sphere-2.5K", "laplace", T, (0.5,)),
    ("sphere-2.5K", "out10", T, (0.25,)),
    ("torus-5.8K", "student", C, (0.5,)), ("torus-5.8K", "vary", T, (0.15,)),
    ("torus-5.8K", "out30", C, (0.25,)),
    ("spot", "quant", T, (0.5,)), ("spot", "view", C, (0.5,)), ("spot", "out3", T, (0.25,)),
    ("fandisk", "laplace", C, (0.5,)), ("fandisk", "quant", T, (0.5,)),
    ("fandisk", "vary", C, (0.15,)),
    ("box", "view", T, (0.5,)), ("box", "student", C, (0.5,)),
    ("circle-2d", "laplace", C, (0.5,)), ("circle-2d", "out10", T, (0.25,)),
    ("trefoil-3d", "quant", C, (0.5,)), ("trefoil-3d", "student", T, (0.5,)),
    ("cloud-sphere", "view", T, (0.5,)), ("cloud-sphere", "laplace", C, (0.5,)),
    ("cloud-fandisk", "out10", T, (0.25,)), ("cloud-fandisk", "student", C, (0.5,)),
    # --- issue 21: new shapes ------------------------------------------------------------------
    ("sphere-irr", "iso", T, (0.25,)), ("sphere-irr", "aniso", C, (0.5,)),
    ("sphere-irr", "vary", T, (0.15,)), ("sphere-irr", "out3", C, (0.25,)),
    ("hemisphere", "iso", C, (0.25,)), ("hemisphere", "view", T, (0.5,)),
    ("hemisphere", "laplace", T, (0.5,)), ("hemisphere", "out10", C, (0.25,)),
    ("saddle-irr", "iso", C, (0.25,)), ("saddle-irr", "student", T, (0.5,)),
    ("saddle-irr", "quant", C, (0.5,)), ("saddle-irr", "out30", T, (0.25,)),
    ("terrain", "view", T, (0.5,)), ("terrain", "quant", C, (0.5,)),
    ("terrain", "laplace", C, (0.5,)), ("terrain", "out10", T, (0.25,)),
    ("terrain", "iso", T, (0.25,)),
    ("dem", "view", C, (0.5,)), ("dem", "quant", T, (0.5,)), ("dem", "student", T, (0.5,)),
    ("dem", "vary", C, (0.15,)),
    ("torusknot", "iso", T, (0.25,)), ("torusknot", "gps", C, (0.5,)),
    ("torusknot", "out10", C, (0.25,)),
    ("fig8", "iso", C, (0.25,)), ("fig8", "laplace", T, (0.5,)), ("fig8", "vary", T, (0.15,)),
    ("helix", "quant", T, (0.5,)), ("helix", "aniso", C, (0.5,)), ("helix", "student", C, (0.5,)),
    ("track-2d", "gps", T, (0.5,)), ("track-2d", "iso", C, (0.25,)),
    ("track-2d", "out30", C, (0.25,)), ("track-2d", "out3", T, (0.25,)),
    ("cloud-dens-sphere", "iso", T, (0.25,)), ("cloud-dens-sphere", "aniso", C, (0.5,)),
    ("cloud-dens-sphere", "vary", C, (0.15,)), ("cloud-dens-sphere", "out10", T, (0.25,)),
    ("cloud-dens-terrain", "view", T, (0.5,)), ("cloud-dens-terrain", "out3", C, (0.25,)),
    ("cloud-dens-terrain", "laplace", C, (0.5,)), ("cloud-dens-terrain", "student", T, (0.5,)),
)

#: Issue 31: (shape, noise model, half, levels, phenomenon). A family already in :data:`_TABLE`
#: (e.g. fandisk x iso) keeps its half there; the levels here are new ones.
_TABLE31: tuple[tuple[str, str, str, tuple[float, ...], str], ...] = (
    # uniform Gaussian noise on CAD shapes with corners and creases
    ("cube-6K", "iso", C, (0.05, 0.1, 0.25), "cad"), ("stepblock", "iso", C, (0.05, 0.1), "cad"),
    ("box", "iso", C, (0.05,), "cad"), ("fandisk", "normal", C, (0.05,), "cad"),
    ("bracket", "iso", T, (0.05, 0.1, 0.25), "cad"), ("cube-6K", "normal", T, (0.05, 0.1), "cad"),
    ("fandisk", "iso", T, (0.05,), "cad"), ("stepblock", "normal", T, (0.1,), "cad"),
    # quantized coordinates (grid step = level x h)
    ("sphere-2.5K", "quant", C, (0.5, 1.0), "quant"), ("stepblock", "quant", C, (1.0,), "quant"),
    ("helicoid", "quant", T, (0.5, 1.0), "quant"), ("bracket", "quant", T, (1.0,), "quant"),
    # high noise on regular meshes
    ("sphere-2.5K", "iso", C, (1.0, 1.5), "high"), ("torus-5.8K", "normal", C, (1.0, 1.5), "high"),
    ("torus-5.8K", "iso", T, (1.0, 1.5), "high"), ("sphere-2.5K", "normal", T, (1.0, 1.5), "high"),
    ("terrain", "iso", T, (1.0,), "high"),
    # GPS-like tracks: corners, uneven spacing, AR(1) noise
    ("track-corners-a", "gps", C, (0.1, 0.5), "gps"),
    ("track-corners-b", "gps", T, (0.1, 0.5), "gps"),
    ("track-recorded", "gps", T, (0.1, 0.5), "gps"),
    ("track-recorded", "clean", C, (0.0,), "clean"),
    # clouds with stray points 10 - 50 spacings off the surface
    ("cloud-sphere", "stray2", C, (0.25,), "stray"),
    ("cloud-dens-terrain", "stray05", C, (0.1,), "stray"),
    ("cloud-torus", "stray1", T, (0.25,), "stray"), ("cloud-fandisk", "stray2", T, (0.1,), "stray"),
    # noise-free inputs (level 0)
    ("cube-6K", "clean", C, (0.0,), "clean"), ("stepblock", "clean", C, (0.0,), "clean"),
    ("track-corners-a", "clean", C, (0.0,), "clean"), ("bracket", "clean", T, (0.0,), "clean"),
    ("helicoid", "clean", T, (0.0,), "clean"), ("track-corners-b", "clean", T, (0.0,), "clean"),
)


def _split() -> dict[tuple[str, str], str]:
    out = {(s, nz): half for s, nz, half, _ in _TABLE}
    for s, nz, half, _, _ in _TABLE31:
        if out.setdefault((s, nz), half) != half:
            raise ValueError(f"family {s} x {nz} is in both halves")
    return out


#: (shape, noise model) -> half.
SPLIT: dict[tuple[str, str], str] = _split()

#: The cases the halves' tables run (issue 21's families), in table order.
CASES: list[str] = [f"{s}/{nz}-{lv:g}" for s, nz, _, levels in _TABLE for lv in levels]


#: Issue-31 cases drawn with several seeds (``key#1`` ... ``key#k-1`` besides ``key``): the
#: misses that occur on some draws only (the step block's crease sigma^: 4 of 8 draws at iso
#: 0.1 h, 1 of 8 at normal 0.1 h; the 6K cube's noise weights at 0.05 h: every draw; a track's
#: correlated sigma^, which varies from draw to draw: 0.74 - 1.36 sigma).
REPEATS31: dict[str, int] = {"stepblock/iso-0.1": 8, "stepblock/normal-0.1": 8,
                             "cube-6K/iso-0.05": 4, "cube-6K/normal-0.05": 4,
                             **dict.fromkeys(("track-corners-a/gps-0.1", "track-corners-a/gps-0.5",
                                              "track-corners-b/gps-0.1", "track-corners-b/gps-0.5"),
                                             4)}


def _cases31() -> dict[str, str]:
    out = {}
    for s, nz, _, levels, ph in _TABLE31:
        for lv in levels:
            key = f"{s}/{nz}-{lv:g}"
            out[key] = ph
            out.update({f"{key}#{k}": ph for k in range(1, REPEATS31.get(key, 1))})
    return out


#: Issue 31's cases (:mod:`benchmarks.quality.issue31`), in table order, and their phenomenon.
PHENOMENON: dict[str, str] = _cases31()
CASES31: list[str] = list(PHENOMENON)


def half_of(key: str) -> str:
    """``"calibration"`` or ``"test"`` for a case key ``"<shape>/<noise>-<level>"``."""
    shape, spec = key.split("/")
    noise = spec.rsplit("-", 1)[0]
    try:
        return SPLIT[(shape, noise)]
    except KeyError:
        raise KeyError(f"family {shape} x {noise} is not in families.SPLIT") from None


def half_cases(half: str) -> list[str]:
    """The issue-21 cases of one half (``"calibration"``, ``"test"`` or ``"all"``)."""
    return [k for k in CASES if half == "all" or half_of(k) == half]


def issue31_cases(half: str) -> list[str]:
    """Issue 31's cases of one half (``"calibration"``, ``"test"`` or ``"all"``)."""
    return [k for k in CASES31 if half == "all" or half_of(k) == half]
