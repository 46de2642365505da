#!/usr/bin/env bash
# slot.sh SCENE INTEGRATORS [SEED]: one locked 60 s convergence run (session 29: unconnectable_pass
# on the repo scenes with Dirac lobes not measured in session 28), from a directory holding this script;
# M = the repo root, MR = the mcmc-render binary. Each scene at its reference's size; the reference's
# variance image (where one exists) corrects the error.
set -e
M=${M:-/work/main}; MR=${MR:-mcmc-render}; S=$1; I=$2; SEED=${3:-0}
case $S in
  cornell-glossy-glass) SPP=2048;;
  interior-window) SPP=2048;;
  mirror-balls|ring|caustic-sds) SPP=8192;;
  smallvcm-box|cornell-plastic|cornell-thindielectric|door-ajar-real|door-ajar) SPP=4096;;
  cornell-box) SPP=1024;;
  *) echo "unknown scene $S"; exit 2;;
esac
read W H < <(python3 -c "import json;d=json.load(open('$M/scenes/reference/$S.json'));print(d['width'],d['height'])")
VAR=(); [ -f $M/scenes/reference/$S.var.exr ] && VAR=(--reference-variance $M/scenes/reference/$S.var.exr --reference-spp $SPP)
SUF=$([ "$SEED" = 0 ] || echo "-seed$SEED")
echo "$S $I start $(date -u +%T) $(uptime)" >> slot.log
flock /work/measure.lock /usr/bin/time -f "%U user %S sys %e wall" -a -o slot.log nice -n -15 $MR convergence $M/scenes/$S.xml -D width=$W -D height=$H \
  --reference $M/scenes/reference/$S.exr "${VAR[@]}" \
  --integrators "$I" --time 60 --checkpoints 4 --threads 2 --seed $SEED \
  --images ${TAG:-img}$SUF-$S --out ${TAG:-pathspace}-$S-s29$SUF.csv
echo "$S end $(date -u +%T) $(uptime)" >> slot.log
