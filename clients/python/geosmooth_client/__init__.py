"""Client of the geosmooth HTTP service: smoothing of meshes, curves and point clouds.

Pure Python (httpx only: no SuiteSparse, no compiler)::

    from geosmooth_client import Client

    with Client("http://127.0.0.1:8000", api_key="...") as client:
        result = client.smooth("bunny.ply", tau=2e-4, progress=print)
        result.save("bunny-smooth.ply")
        print(result.report.lam, result.report.phi, result.report.converged)

:class:`AsyncClient` has the same methods as coroutines. Errors are typed
(:mod:`geosmooth_client.errors`), built from the service's problem details.
"""

from geosmooth_client._protocol import ProgressCallback, RetryPolicy
from geosmooth_client.async_client import AsyncClient
from geosmooth_client.client import Client
from geosmooth_client.errors import (
    ApiError,
    BadRequest,
    Conflict,
    ConnectionFailed,
    FieldError,
    Forbidden,
    GeosmoothClientError,
    InsufficientStorage,
    InvalidInput,
    JobCancelled,
    JobFailed,
    JobInterrupted,
    NotFound,
    PayloadTooLarge,
    RateLimited,
    ServerError,
    ServiceUnavailable,
    Unauthorized,
    UnsupportedMediaType,
    WaitTimeout,
)
from geosmooth_client.models import (
    FINISHED,
    Job,
    JobLinks,
    JobList,
    JobProblem,
    JobProgress,
    PageLinks,
    Report,
)
from geosmooth_client.result import Arrays, AsyncResult, Result

__version__ = "0.1.0"

__all__ = [
    "FINISHED",
    "ApiError",
    "Arrays",
    "AsyncClient",
    "AsyncResult",
    "BadRequest",
    "Client",
    "Conflict",
    "ConnectionFailed",
    "FieldError",
    "Forbidden",
    "GeosmoothClientError",
    "InsufficientStorage",
    "InvalidInput",
    "Job",
    "JobCancelled",
    "JobFailed",
    "JobInterrupted",
    "JobLinks",
    "JobList",
    "JobProblem",
    "JobProgress",
    "NotFound",
    "PageLinks",
    "PayloadTooLarge",
    "ProgressCallback",
    "RateLimited",
    "Report",
    "Result",
    "RetryPolicy",
    "ServerError",
    "ServiceUnavailable",
    "Unauthorized",
    "UnsupportedMediaType",
    "WaitTimeout",
    "__version__",
]
