"""GEOSMOOTH_QUEUE=local: SQLite store, worker pool, maintenance (compose profile 'embedded')."""
