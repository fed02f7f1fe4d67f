"""Shared by the readers and writers: text parsing, numbers, welding, normals, geographic frames."""
