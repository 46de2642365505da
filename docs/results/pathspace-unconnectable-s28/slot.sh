#!/usr/bin/env bash
# slot.sh SCENE INTEGRATORS [SEED]: one locked 60 s convergence run (session 28, unconnectable_pass),
# from the repo root. The RELT scenes at 128x128 against their 6016-spp bdpt references
# (5 checkpoints); caustic-sds and ring at 128x96 against Mitsuba's 8192 spp (4 checkpoints).
set -e
M=.; S=$1; I=$2; SEED=${3:-0}
case $S in
  relt-*) SIZE=(-D width=128 -D height=128); SPP=6016; K=5;;
  *) SIZE=(-D width=128 -D height=96); SPP=8192; K=4;;
esac
SUF=$([ "$SEED" = 0 ] || echo "-seed$SEED")   # seed 0's files have no suffix
echo "$S $I start $(date -u +%T) $(uptime)" >> slot.log
flock /work/measure.lock /usr/bin/time -f "%U user %S sys %e wall" -a -o slot.log nice -n -15 mcmc-render convergence $M/scenes/$S.xml "${SIZE[@]}" \
  --reference $M/scenes/reference/$S.exr --reference-variance $M/scenes/reference/$S.var.exr --reference-spp $SPP \
  --integrators "$I" --time 60 --checkpoints $K --threads 2 --seed $SEED \
  --images img$SUF-$S --out pathspace-$S-s28$SUF.csv
echo "$S end $(date -u +%T) $(uptime)" >> slot.log
