"""After the solve: shape guards, volume/area rescaling, spectrum, the report's diagnostics."""
