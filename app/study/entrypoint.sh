#!/bin/sh
# The image's entrypoint: `tomstudy serve` on 0.0.0.0:8000 (production mode), plus any
# serve options given as arguments (e.g. `--workers 2`). Arguments that start with a
# command run it instead (`docker compose run --rm server tomstudy preview-link`).
#
# First start: when the data volume holds no trial bank for a served study, the server
# first builds the study the way `make serve` does (`serve --prepare`: simulate both
# worlds, train Ours and the VAE, build the bank; 2.5 to 4 minutes on 2 cores, README
# "Going live"). A bank that exists is never rebuilt here, even if a copied-in var/ no
# longer matches the paths in its meta.json: participants must keep seeing the same trials.
set -eu

case "${1:-}" in
  "" | -*) ;;
  *) exec "$@" ;;
esac

studies=paper_study  # `tomstudy serve`'s default
previous=
for arg in "$@"; do
  case "$arg" in --study=*) studies=${arg#--study=} ;; esac
  if [ "$previous" = --study ]; then studies=$arg; fi
  previous=$arg
done

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
