# The loceval service in one container: the API, the web page and the in-process queue consumer.
#
#   docker build -t loceval .
#   docker run -p 8000:8000 -v loceval-data:/data loceval
#
# On the first start with an empty /data the log shows the API key of project "default" once
# (`docker logs`); more keys: `docker exec CONTAINER .venv/bin/loceval keys create --project NAME`.
# Settings are LOCEVAL_* environment variables (see service/settings.py), e.g.
# LOCEVAL_DATABASE_URL=postgresql+psycopg://... and LOCEVAL_QUEUE_URL=redis://... to scale out
# with more containers running `.venv/bin/loceval worker` on the same volume, or, with no volume
# shared, on an S3-compatible bucket:
#
#   docker run -p 8000:8000 -e LOCEVAL_DATABASE_URL=... -e LOCEVAL_QUEUE_URL=... \
#       -e LOCEVAL_BLOB_URL=s3://BUCKET/PREFIX -e AWS_ENDPOINT_URL=https://STORE \
#       -e AWS_ACCESS_KEY_ID=... -e AWS_SECRET_ACCESS_KEY=... -e AWS_REGION=... \
#       loceval .venv/bin/loceval serve --host 0.0.0.0 --port 8000 --no-consumer
#   docker run (the same -e ...) loceval .venv/bin/loceval worker
#
# /data then holds only each container's input cache (LOCEVAL_BLOB_CACHE_BYTES); boto3 is in
# the locked runtime dependencies. `loceval storage migrate` moves an existing /data into the bucket.
#
# It builds with the classic builder and with BuildKit (no cache mounts, no syntax line to
# pull). BASE is any Debian bookworm image with python3 (3.11) and python3-venv on the PATH:
# the official slim image (Python in /usr/local/bin) or a debootstrap of bookworm (Debian's
# python3 in /usr/bin), which tests/service/test_container.py builds where no registry answers.
ARG BASE=python:3.11-slim-bookworm
FROM ${BASE}

# No .pyc files written at run time, log lines reach `docker logs` at once, no pip nagging, no pip
# download cache left in a layer.
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1

# make for `make setup` and tini as process 1 (below); nothing else from the system: the PDF
# reports are typeset by Typst (a wheel) in matplotlib's own fonts. Then drop apt's lists.
RUN apt-get update \
    && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
        make \
        tini \
    && rm -rf /var/lib/apt/lists/*

# The unprivileged user the service runs as, with a home for matplotlib's and fontconfig's
# caches. /data (uploads, artifacts, SQLite database and queue) belongs to it; it must exist
# with this owner before the VOLUME line, or a fresh named volume would be owned by root.
RUN groupadd --system --gid 10001 loceval \
    && useradd --system --uid 10001 --gid loceval --create-home --home-dir /home/loceval \
        --shell /usr/sbin/nologin loceval \
    && mkdir /data \
    && chown loceval:loceval /data

WORKDIR /app

# The locked dependencies first, in a layer of their own that only a change of the lock files
# (or the Makefile) rebuilds: an edit of the code then costs seconds, not minutes of pip. This
# is the first half of `make setup`'s recipe with the Makefile's own variables; the
# `make setup` below stays the install of record (it finds these already satisfied).
COPY Makefile ./
COPY requirements/ requirements/
RUN make --eval='locked-deps: ; $(PYTHON) -m venv $(VENV) && $(PIP_LOCKED) -r requirements/build.lock -r requirements/runtime.lock' locked-deps

# The project (.dockerignore keeps out .venv, .git, outputs and caches). It stays owned by
# root: the service can read its code and templates but not change them.
COPY . .

# Install exactly as the README does: `make setup` creates .venv and installs the hash-pinned
# requirements/runtime.lock (runtime dependencies, service included; no dev tools) and then
# loceval itself, so the path tested outside the container is the container's path.
RUN make setup

# loceval's own bytecode, compiled once here (pip compiled the dependencies'): with
# PYTHONDONTWRITEBYTECODE every process would otherwise compile it again at start-up (each
# CLI command, each job's process), and the user the service runs as may not write it here.
RUN .venv/bin/python -m compileall -q loceval exporters service

# Where the service keeps its state; mount a volume here to keep it across containers.
ENV LOCEVAL_DATA_DIR=/data
VOLUME /data

EXPOSE 8000

# Liveness through the standard library (the image has no curl): /healthz answers 200
# {"status": "ok"}; urlopen raises on errors and refusals, and any exception exits non-zero.
# `docker run --health-interval 1s` checks more often (the tests do).
HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 \
    CMD ["/app/.venv/bin/python", "-c", "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4)"]

USER loceval

# tini is process 1 and passes `docker stop`'s SIGTERM on to the service. Process 1 gets no
# signal it has no handler for: in the seconds before `loceval serve` has installed uvicorn's
# handlers (imports, migrations) a stop would wait out Docker's 10 s and end in SIGKILL.
# uvicorn shuts down gracefully and then re-raises SIGTERM (exit 143); -e 143 makes that 0.
ENTRYPOINT ["/usr/bin/tini", "-e", "143", "--"]

# Listen on all interfaces inside the container; publish the port with -p.
CMD [".venv/bin/loceval", "serve", "--host", "0.0.0.0", "--port", "8000"]
