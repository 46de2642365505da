#!/bin/sh
# Issue 15 (session 30) on scenes/glass-knot.xml: all integrators side by side in one locked
# convergence run per seed (120 s each, order reversed for seed 2), corrected errors against the
# Mitsuba reference (262 144 spp with its variance image). Then: python3 summary.py *.csv
set -u
BIN=${BIN:-target/release/mcmc-render}
cd "$(dirname "$0")/../../.."
for SEED in 1 2; do
  if [ $SEED = 1 ]; then
    LIST=pt,pssmlt-bdpt,mmlt,mlt,mept,tempered-pssmlt,tempered-mmlt
  else
    LIST=tempered-mmlt,tempered-pssmlt,mept,mlt,mmlt,pssmlt-bdpt,pt
  fi
  echo "seed $SEED start $(date -u +%T) load: $(cat /proc/loadavg)" >> docs/results/tempered-glass-knot-s30/load.txt
  flock /work/measure.lock /usr/bin/time -f '%e s wall %U user %S sys' nice -n -15 "$BIN" convergence scenes/glass-knot.xml \
    --reference scenes/reference/glass-knot.exr --reference-variance scenes/reference/glass-knot.var.exr \
    --reference-spp 262144 --integrators "$LIST" --time 120 --checkpoints 6 --threads 2 --seed $SEED \
    --out docs/results/tempered-glass-knot-s30/glass-knot-s30-seed$SEED.csv --images docs/results/tempered-glass-knot-s30/img-s$SEED > docs/results/tempered-glass-knot-s30/log-s$SEED.txt 2>&1
  echo "seed $SEED end $(date -u +%T) load: $(cat /proc/loadavg)" >> docs/results/tempered-glass-knot-s30/load.txt
done
# Seed 3 (run afterwards, the three integrators of the goal only):
#   flock /work/measure.lock nice -n -15 "$BIN" convergence scenes/glass-knot.xml [the flags above] \
#     --integrators tempered-pssmlt,pssmlt-bdpt,mept --seed 3 \
#     --out docs/results/tempered-glass-knot-s30/glass-knot-s30-seed3.csv --images docs/results/tempered-glass-knot-s30/img-s3
