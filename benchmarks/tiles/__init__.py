"""Benchmarks of tiled runs (issue 23): stitched against untiled at 1M, a 20M-point LAS."""
