"""``python -m geosmooth``: the ``geosmooth`` command (:func:`service.cli.main`)."""

from service.cli.main import main

if __name__ == "__main__":
    raise SystemExit(main())
