"""The CHOLMOD wrapper, CG, Lanczos, symbolic factor size, caches, memory and threads."""
