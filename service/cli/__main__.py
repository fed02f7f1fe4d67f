"""``python -m service.cli``: the ``geosmooth`` command."""

from service.cli.main import main

raise SystemExit(main())
