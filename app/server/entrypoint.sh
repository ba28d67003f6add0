#!/bin/sh
# The image's entrypoint (under dumb-init, which forwards `docker stop`'s SIGTERM): `tomstudy
# serve` on 0.0.0.0:8000 (production mode), plus any serve options given as arguments (e.g.
# `--workers 2`, `--port 9000`: the last one given wins). Arguments that start with a
# command run it instead (`docker compose run --rm server tomstudy preview-link`).
#
# Every start is `serve --prepare`, which builds nothing for a study served from the bundle
# that ships in the image (the paper's study: it serves at once) nor for a `built` study whose
# bundle the data volume already holds. Only a `built` study without one is built first
# (simulate, train every seed, build the bank, freeze: minutes; docs/run/go-live.md, "Going
# live"). A bundle that exists is never rebuilt here: participants must keep seeing the same
# trials.
#
# Files are made with umask 077: the database, the trial bank and the models are readable by
# the container's user only. The HEALTHCHECK reads the address to ask from /tmp/tomstudy-healthz.
#
# Forwarded client addresses are trusted only from TOMSTUDY_TRUSTED_PROXIES (default
# 127.0.0.1; `tomstudy serve` refuses `*` and a FORWARDED_ALLOW_IPS it would not read).
#
# A data dir this user cannot write (a bind mount owned by someone else) is refused by
# `tomstudy serve` with what to do, before anything is built.
set -eu
umask 077

case "${1:-}" in
  "" | -*) ;;
  *) exec "$@" ;;
esac

host=0.0.0.0
port=8000
previous=
for arg in "$@"; do
  case "$arg" in
    --host=*) host=${arg#--host=} ;;
    --port=*) port=${arg#--port=} ;;
  esac
  case "$previous" in
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

exec tomstudy serve --host 0.0.0.0 --port 8000 --prepare "$@"
