#!/bin/sh
# The image's entrypoint: `tomstudy serve` on 0.0.0.0:8000 (production mode), plus any
# serve options given as arguments (e.g. `--workers 2`). Arguments that start with a
# command run it instead (`docker compose run --rm server tomstudy preview-link`).
#
# Every start is `serve --prepare`, which builds nothing for a study served from the bundle
# that ships in the image (the paper's study: it serves at once) nor for a `built` study whose
# bundle the data volume already holds. Only a `built` study without one is built first
# (simulate, train every seed, build the bank, freeze: minutes, README "Going live"). A bundle
# that exists is never rebuilt here: participants must keep seeing the same trials.
set -eu

case "${1:-}" in
  "" | -*) ;;
  *) exec "$@" ;;
esac

exec tomstudy serve --host 0.0.0.0 --port 8000 --prepare "$@"
