"""geosmooth JSON: the codec and the schema shared with the HTTP API."""
