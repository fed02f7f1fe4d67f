"""Issue 21 items 4-5 (helper *ends*): curves, grids and clouds against VTK, Taubin and MLS.

Scripts, run from the repository root with the peers installed aside (``PEERS_SITE``, a
``pip install --target`` of pyvista, vtk and pymeshlab, when they are not in the environment)::

    python -m benchmarks.quality.ends.final calibration circle-2d/iso-0.5,wave-2d/iso-0.25,...
    python -m benchmarks.quality.ends.final test knot35/iso-0.5,helix/quant-1,dem/iso-0.5,...
    python -m benchmarks.quality.ends.sinc_test knot35/iso-0.5,...   # windowed-sinc's degree
    python -m benchmarks.quality.ends.cloud_exp cloud-density/aniso-0.5,...
    OMP_NUM_THREADS=1 python -m benchmarks.quality.ends.cost2 CURVES FREE_MESHES

Cases (``cases.case("shape/noise-level")``): the benchmark's shapes plus open curves (wave-2d,
spiral-3d), a (3,5) torus knot (knot35), an open helix (helix), terrain and DEM grids (terrain,
dem), an open hemisphere, a sphere cloud with a 10:1 density change (cloud-density); noises
normal / iso / aniso as the benchmark, ``quant`` (coordinates rounded to level x h) and
``zonly`` (z only). The results are in service/core/README.md ("Issue 21: end conditions").
"""
