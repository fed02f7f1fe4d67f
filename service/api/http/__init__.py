"""What every request meets first: protocol, limits, guards, auth, logs, metrics."""
