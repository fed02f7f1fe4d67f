"""Noise of the input (report section 7's discrepancy principle needs it): the estimate
sigma, local point fits and the robust and per-point data weights omega_i."""
