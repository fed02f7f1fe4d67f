"""Section 6: tau resolved once (given, rms, automatic; rms <-> tau in ``budget``), lambda
found; the tau range; windowed-sinc; max-norm bound.
"""
