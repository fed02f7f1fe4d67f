"""PLY: header, ASCII and binary bodies, writing."""
