# tomstudy study server, CPU only. Mirrors the README's install: torch==2.13.0 first (an
# unpinned resolve pulls gigabytes of CUDA wheels), then the project.
#
#   docker build -t tomstudy .
#   docker run -p 8000:8000 -v "$PWD/var:/app/var" \
#     -e TOMSTUDY_PRODUCTION=1 -e TOMSTUDY_ADMIN_TOKEN=<long random token> \
#     -e DATABASE_URL=postgresql+psycopg://tomstudy:<password>@db-host:5432/tomstudy \
#     tomstudy
#
# Without DATABASE_URL the server uses SQLite in the mounted var/ (one worker). With a
# PostgreSQL DATABASE_URL (psycopg 3) it can run several workers: add `--workers 4` to the
# command. The trial bank and checkpoints are read from var/; build them once with
# `docker run ... tomstudy tomstudy serve --prepare` or copy an existing var/ in.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    TOMSTUDY_DATA_DIR=/app/var

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
CMD ["tomstudy", "serve", "--host", "0.0.0.0", "--port", "8000", "--study", "paper_study"]
