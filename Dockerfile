# tomstudy study server, CPU only. Mirrors the README's install: torch==2.13.0 first (an
# unpinned resolve pulls gigabytes of CUDA wheels), then the project.
#
#   docker build -t tomstudy .
#   umask 077   # tomstudy.env holds the key to every participant's data: keep it out of git
#   echo "TOMSTUDY_ADMIN_TOKEN=$(python3 -c 'import secrets;print(secrets.token_urlsafe(32))')" \
#     > tomstudy.env
#   docker run --env-file tomstudy.env -p 127.0.0.1:8000:8000 -v "$PWD/var:/app/var" tomstudy
#
# The image runs in production mode (TOMSTUDY_PRODUCTION=1 below): it refuses to start
# without a TOMSTUDY_ADMIN_TOKEN of at least 32 characters, and /docs, /redoc and
# /openapi.json answer 404. It speaks plain HTTP: publish the port on 127.0.0.1 (as above)
# and put a reverse proxy that terminates HTTPS in front of it (README, "Hosting on the
# internet"); never publish it on a public address as is.
#
# compose.yaml runs this image with PostgreSQL (README, "Going live"). Without DATABASE_URL
# the server uses SQLite in the mounted var/ (one worker only). With a PostgreSQL
# DATABASE_URL (psycopg 3), e.g. a line
# DATABASE_URL=postgresql+psycopg://tomstudy:<password>@db-host:5432/tomstudy in the env
# file, it can run several workers: append `--workers 4` to the run command (arguments are
# serve options, see app/study/entrypoint.sh). The paper's study is served from the frozen
# bundle in study_configs/bundles/ (copied in below), so the first start trains nothing; a
# study of your own with `bundle: built` is built into var/ on its first start (minutes, see
# the README). HEALTHCHECK asks /healthz, which checks the database; its start period covers
# such a first build.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    TOMSTUDY_DATA_DIR=/app/var \
    TOMSTUDY_PRODUCTION=1

WORKDIR /app

RUN pip install --upgrade pip \
 && pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu

COPY pyproject.toml README.md ./
COPY app ./app
COPY analysis ./analysis
COPY frontend ./frontend
COPY study_configs ./study_configs
# editable: the server finds frontend/ and study_configs/ beside the app package
RUN pip install -e .

RUN useradd --create-home tomstudy && mkdir -p /app/var && chown tomstudy /app/var
USER tomstudy

EXPOSE 8000
VOLUME ["/app/var"]
# urlopen raises (exit 1) on the 503 /healthz answers when the database is down
HEALTHCHECK --interval=30s --timeout=15s --start-period=10m \
  CMD python -c "import urllib.request as u; u.urlopen('http://127.0.0.1:8000/healthz', timeout=12)"
# serves on 0.0.0.0:8000 inside the container; publish it on 127.0.0.1 only
ENTRYPOINT ["/app/app/study/entrypoint.sh"]
