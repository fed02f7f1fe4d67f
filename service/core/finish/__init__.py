"""After the solve: the tangential step, volume/area rescaling, folds and max-norm clipping."""
