#!/usr/bin/env bash
# slot.sh SCENE INTEGRATORS: one locked 60 s convergence run at 128x128 (session 28, unconnectable_pass)
set -e
M=.; S=$1; I=$2
echo "$S $I start $(date -u +%T) $(uptime)" >> slot.log
flock /work/measure.lock /usr/bin/time -f "%U user %S sys %e wall" -a -o slot.log nice -n -15 mcmc-render convergence $M/scenes/$S.xml -D width=128 -D height=128 \
  --reference $M/scenes/reference/$S.exr --reference-variance $M/scenes/reference/$S.var.exr --reference-spp 6016 \
  --integrators "$I" --time 60 --checkpoints 5 --threads 2 --seed 0 \
  --images img-$S --out pathspace-$S-s28.csv
echo "$S end $(date -u +%T) $(uptime)" >> slot.log
