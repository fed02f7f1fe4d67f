"""GEOSMOOTH_QUEUE=rq: Redis store, RQ tasks and workers, blob store (compose profile
'distributed').
"""
