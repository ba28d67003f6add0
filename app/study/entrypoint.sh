#!/bin/sh
# The image's entrypoint (under dumb-init, which forwards `docker stop`'s SIGTERM): `tomstudy
# serve` on 0.0.0.0:8000 (production mode), plus any serve options given as arguments (e.g.
# `--workers 2`, `--port 9000`: the last one given wins). Arguments that start with a
# command run it instead (`docker compose run --rm server tomstudy preview-link`).
#
# Files are made with umask 077: the database, the trial bank and the models are readable by
# the container's user only. The HEALTHCHECK reads the address to ask from /tmp/tomstudy-healthz.
#
# First start: when the data volume holds no trial bank for a served study, the server
# first builds the study the way `make serve` does (`serve --prepare`: simulate both
# worlds, train Ours and the VAE, build the bank; 2.5 to 4 minutes on 2 cores, README
# "Going live"). A bank that exists is never rebuilt here, even if a copied-in var/ no
# longer matches the paths in its meta.json: participants must keep seeing the same trials.
# A data dir this user cannot write (a bind mount owned by someone else) is refused by
# `tomstudy serve` with what to do, before anything is built.
set -eu
umask 077

case "${1:-}" in
  "" | -*) ;;
  *) exec "$@" ;;
esac

studies=paper_study  # `tomstudy serve`'s default
host=0.0.0.0
port=8000
previous=
for arg in "$@"; do
  case "$arg" in
    --study=*) studies=${arg#--study=} ;;
    --host=*) host=${arg#--host=} ;;
    --port=*) port=${arg#--port=} ;;
  esac
  case "$previous" in
    --study) studies=$arg ;;
    --host) host=$arg ;;
    --port) port=$arg ;;
  esac
  previous=$arg
done
case "$host" in
  0.0.0.0 | "::" | "[::]") ask=127.0.0.1 ;;
  *:*) ask="[$host]" ;;
  *) ask=$host ;;
esac
echo "http://$ask:$port/healthz" > "${TOMSTUDY_HEALTHZ_FILE:-/tmp/tomstudy-healthz}"

data_dir=${TOMSTUDY_DATA_DIR:-/app/var}
prepare=
for study in $(echo "$studies" | tr ',' ' '); do
  if [ ! -f "$data_dir/trials/$study/bank.json" ]; then
    echo "first start: no trial bank for $study in $data_dir; building the study" \
      "(simulate, train, build-trials) before serving"
    prepare=--prepare
  fi
done

exec tomstudy serve --host 0.0.0.0 --port 8000 $prepare "$@"
