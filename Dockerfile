# syntax=docker/dockerfile:1
# geosmooth HTTP service.
#   docker build -t geosmooth .
#   docker run -p 8000:8000 -v geosmooth-data:/data geosmooth
# Base: Debian 12 (bookworm); SuiteSparse 5.12 (libcholmod3) matches scikit-sparse 0.4.16.

ARG PYTHON_IMAGE=python:3.11-slim-bookworm

# ---------------------------------------------------------------------------- builder
FROM ${PYTHON_IMAGE} AS builder

ENV PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    PYTHONDONTWRITEBYTECODE=1

WORKDIR /src
# The one place that installs Debian packages (also used by make and CI).
COPY scripts/install-system-deps.sh scripts/install-system-deps.sh
RUN scripts/install-system-deps.sh --build \
    && rm -rf /var/lib/apt/lists/*

RUN python -m venv /opt/geosmooth \
    && /opt/geosmooth/bin/pip install --upgrade pip setuptools wheel
# Dependencies first (this layer stays cached while only the sources change; scikit-sparse is
# compiled here against Debian's SuiteSparse), then the package itself.
COPY pyproject.toml README.md ./
# The pure-Python client (a dependency of the server package, not on PyPI) before the rest.
COPY clients/python/ clients/python/
RUN /opt/geosmooth/bin/pip install ./clients/python
RUN /opt/geosmooth/bin/python -c "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']))" > /tmp/requirements.txt \
    && /opt/geosmooth/bin/pip install -r /tmp/requirements.txt
COPY service/ service/
COPY geosmooth/ geosmooth/
RUN /opt/geosmooth/bin/pip install --no-deps . \
    && /opt/geosmooth/bin/python -c "import sksparse.cholmod, service.api.app, service.cli, geosmooth, geosmooth_client"

# ---------------------------------------------------------------------------- runtime
FROM ${PYTHON_IMAGE} AS runtime

LABEL org.opencontainers.image.title="geosmooth" \
      org.opencontainers.image.description="Smoothing of meshes, polylines and point clouds over HTTP" \
      org.opencontainers.image.licenses="BSD-3-Clause"

COPY scripts/install-system-deps.sh /tmp/install-system-deps.sh
RUN /tmp/install-system-deps.sh --runtime \
    && rm -rf /var/lib/apt/lists/* /tmp/install-system-deps.sh

COPY --from=builder /opt/geosmooth /opt/geosmooth

RUN groupadd --system --gid 10001 geosmooth \
    && useradd --system --uid 10001 --gid geosmooth --home-dir /data --no-create-home \
       --shell /usr/sbin/nologin geosmooth \
    && mkdir -p /data \
    && chown geosmooth:geosmooth /data

ENV PATH=/opt/geosmooth/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    GEOSMOOTH_DATA_DIR=/data

USER geosmooth
WORKDIR /data
VOLUME ["/data"]
EXPOSE 8000

# No curl in slim images: probe /healthz with the venv's Python.
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import sys, urllib.request; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4).status == 200 else 1)"]

# SIGTERM (docker stop) shuts down gracefully: running jobs are put back in the queue.
STOPSIGNAL SIGTERM
CMD ["geosmooth", "serve", "--host", "0.0.0.0", "--port", "8000", "--data-dir", "/data"]
