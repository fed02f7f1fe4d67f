"""Benchmarks of geosmooth: solver comparison (report fig. 8) and peer smoothing libraries.

Run ``python -m benchmarks [solvers|peers|all] [--quick] [--sizes ...] [--out DIR]``.
Not part of the installed package and not run by CI.
"""
