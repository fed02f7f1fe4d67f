"""The RQ task path stored in Redis with every enqueued job (``RUN_TASK``).

Jobs enqueued before the task moved to :mod:`service.jobs.distributed.tasks` name this module;
it stays so that they, and any worker of either layout, still resolve ``run_job``.
"""

from service.jobs.distributed.tasks import run_job

__all__ = ["run_job"]
