"""Wavefront OBJ: reading and writing."""
