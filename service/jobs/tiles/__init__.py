"""A tiled job's tiles: on local worker processes (``local``) or as RQ tasks on any
worker (``rq``)."""
