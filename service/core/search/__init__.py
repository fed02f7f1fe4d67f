"""Section 6: tau resolved once (given, rms, automatic), lambda found; the tau range;
windowed-sinc; max-norm bound.
"""
