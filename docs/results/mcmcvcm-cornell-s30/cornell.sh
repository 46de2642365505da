#!/bin/sh
# Issue 16 (session 30): the plain Cornell box with mcmc-vcm at light_subpaths=4 beside 1, vcm and pt,
# 30 s each, one locked convergence run per seed, order reversed for seed 1.
# The committed CSVs were made by a build whose default was light_subpaths=4, so their
# "mcmc-vcm" rows are light_subpaths=4; this script names it explicitly.
set -u
BIN=${BIN:-target/release/mcmc-render}
cd "$(dirname "$0")/../../.."
for SEED in 0 1; do
  if [ $SEED = 0 ]; then
    LIST=pt,vcm,mcmc-vcm+light_subpaths=4,mcmc-vcm+light_subpaths=1
  else
    LIST=mcmc-vcm+light_subpaths=1,mcmc-vcm+light_subpaths=4,vcm,pt
  fi
  echo "seed $SEED start $(date -u +%T) load: $(cat /proc/loadavg)" >> docs/results/mcmcvcm-cornell-s30/load.txt
  flock /work/measure.lock /usr/bin/time -f '%e s wall %U user %S sys' nice -n -15 "$BIN" convergence scenes/cornell-box.xml \
    --reference scenes/reference/cornell-box.exr --integrators "$LIST" --set alpha=1 \
    --time 30 --checkpoints 3 --threads 2 --seed $SEED \
    --out docs/results/mcmcvcm-cornell-s30/mcmcvcm-cornell-box-s30-s$SEED.csv --images docs/results/mcmcvcm-cornell-s30/img-s$SEED > docs/results/mcmcvcm-cornell-s30/log-s$SEED.txt 2>&1
  echo "seed $SEED end $(date -u +%T) load: $(cat /proc/loadavg)" >> docs/results/mcmcvcm-cornell-s30/load.txt
done
