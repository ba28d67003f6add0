# tomstudy study server, CPU only. Every Python dependency is pinned (requirements/runtime.txt,
# `make lock`), torch==2.13.0 is installed first from PyTorch's CPU index (an unpinned resolve
# pulls gigabytes of CUDA wheels), and the dependencies are installed before the code is
# copied, so a code edit rebuilds only the last layers.
#
# The base image: compose.yaml builds on python:3.11-slim pinned by digest (PYTHON_IMAGE);
# the default here is the tag, for builds that must use a local stand-in of it. Do the same
# by hand:
#   docker build --build-arg PYTHON_IMAGE=python:3.11-slim@sha256:<digest from compose.yaml> -t tomstudy .
#   install -d -m 700 -o 10001 var    # the container's user (uid 10001) must own a bind-mounted var/
#   umask 077   # tomstudy.env holds the key to every participant's data: keep it out of git
#   echo "TOMSTUDY_ADMIN_TOKEN=$(python3 -c 'import secrets;print(secrets.token_urlsafe(32))')" \
#     > tomstudy.env
#   echo "TOMSTUDY_ALLOWED_HOSTS=study.example.org" >> tomstudy.env
#   docker run --env-file tomstudy.env -p 127.0.0.1:8000:8000 -v "$PWD/var:/app/var" tomstudy
#
# The image runs in production mode (TOMSTUDY_PRODUCTION=1 below), as uid 10001 (not root),
# under dumb-init (so `docker stop` works at any moment, the first start's build included),
# with umask 077 (the database and the data dir readable by that user only). It refuses to
# start without a TOMSTUDY_ADMIN_TOKEN of at least 32 characters (or TOMSTUDY_ADMIN_TOKEN_FILE),
# answers only the Host names 127.0.0.1, localhost and TOMSTUDY_ALLOWED_HOSTS, and /docs,
# /redoc and /openapi.json answer 404. It speaks plain HTTP: publish the port on 127.0.0.1
# and put a reverse proxy that terminates HTTPS in front of it (docs/run/hosting.md, "Hosting
# on the internet"); never publish it on a public address as is.
#
# Client addresses (rate limits, the researcher lockout) come from X-Forwarded-For only when
# the peer is a proxy named in TOMSTUDY_TRUSTED_PROXIES (addresses or networks; default
# 127.0.0.1, never `*`, which `tomstudy serve` refuses). A proxy on the host reaches the
# container from the Docker network's gateway: put that address in the env file, e.g.
#   echo "TOMSTUDY_TRUSTED_PROXIES=$(docker network inspect bridge \
#     -f '{{(index .IPAM.Config 0).Gateway}}')" >> tomstudy.env
# Without it every participant shares the gateway's address, and so one rate-limit key.
#
# compose.yaml runs this image with PostgreSQL (docs/run/go-live.md, "Going live"). Without
# DATABASE_URL the server uses SQLite in the mounted var/ (one worker only). With a PostgreSQL
# DATABASE_URL (psycopg 3), e.g. a line
# DATABASE_URL=postgresql+psycopg://tomstudy:<password>@db-host:5432/tomstudy in the env
# file, and a shared rate-limit store (TOMSTUDY_RATE_LIMIT_STORAGE=redis://redis-host:6379/0:
# production refuses several workers that each count the limits alone), it can run several
# workers: append `--workers 4` to the run command (arguments are serve options, see
# app/server/entrypoint.sh). The paper's study is served from the frozen
# bundle in study_configs/bundles/ (copied in below), so the first start trains nothing; a
# study of your own with `bundle: built` is built into var/ on its first start (minutes;
# docs/run/go-live.md, "Going live"). HEALTHCHECK asks /healthz (which checks the database)
# on the host and port the server was given; its start period covers such a first build.
ARG PYTHON_IMAGE=python:3.11-slim
FROM ${PYTHON_IMAGE}

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    TOMSTUDY_DATA_DIR=/app/var \
    TOMSTUDY_PRODUCTION=1

WORKDIR /app

# dependencies only: this layer is rebuilt when requirements/runtime.txt changes, not the code
COPY requirements/runtime.txt requirements/runtime.txt
RUN pip install pip==26.3 \
 && pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu \
 && pip install -r requirements/runtime.txt dumb-init==1.2.5.post1

COPY pyproject.toml README.md ./
# `tomstudy prereg` shows the departures from the paper from this page, as it did from the README
COPY docs/reproduce/departures.md ./docs/reproduce/departures.md
COPY app ./app
COPY analysis ./analysis
COPY frontend ./frontend
COPY study_configs ./study_configs
# editable: the server finds frontend/ and study_configs/ beside the app package; every
# dependency is installed above, so this adds only the project itself
RUN pip install --no-deps --no-build-isolation -e . \
 && useradd --uid 10001 --create-home tomstudy \
 && install -d -m 700 -o tomstudy /app/var
# the project's own bytecode, made once here: PYTHONDONTWRITEBYTECODE=1 (and a root-owned /app)
# keeps every worker from writing it, so each start would compile the app again (pip compiled
# site-packages already; an editable install compiles nothing)
RUN python -m compileall -q app analysis
USER 10001

EXPOSE 8000
VOLUME ["/app/var"]
# urlopen raises (exit 1) on the 503 /healthz answers when the database is down; the
# entrypoint writes the address the server listens on
HEALTHCHECK --interval=30s --timeout=15s --start-period=10m \
  CMD ["python", "-c", "import urllib.request as u; a = open('/tmp/tomstudy-healthz').read().strip(); u.urlopen(a, timeout=12)"]
ENTRYPOINT ["dumb-init", "--", "/app/app/server/entrypoint.sh"]
