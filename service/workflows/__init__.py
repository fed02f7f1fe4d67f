"""The use cases, written once (between :mod:`service.io` and :mod:`service.jobs`).

* :mod:`service.workflows.smooth_file`: read -> smooth -> write, streamed or in memory, atomic
  write, errors mapped once; called by the CLI, the job runner, ``POST /v1/smooth`` and the
  :mod:`geosmooth` facade.
* :mod:`service.workflows.admission`: the submit check of a job (estimate, ``tau`` range, dry
  run, tiles), computed once; the :class:`~service.jobs.queue.NewJob` carries its result.
* :mod:`service.workflows.cpu_limit`: the CPU seconds one run may use (``geosmooth smooth
  --time-limit``).
"""
