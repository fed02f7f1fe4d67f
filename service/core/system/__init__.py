"""Eqs. 4, 15, 17: the deviation phi(lambda), fixed points (section 8), free vs normal
displacement.
"""
