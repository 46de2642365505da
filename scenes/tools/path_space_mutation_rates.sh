#!/bin/sh
# Mutations per second per mutation type (issue #13): pssmlt, mlt with
# Mitsuba 0.6's mutation mixture (bidirectional, lens, caustic and
# multi-chain perturbations, weight 1 each), mept and erpt (defaults) on one
# scene, SECONDS each, one after the other under nice -n 5, `uptime` logged
# before and after. The per-type figures are the sidecars' `mutation_types`
# (pssmlt: `mutations_per_second` and `acceptance_per_component`).
# Usage: scenes/tools/path_space_mutation_rates.sh BINARY OUTDIR [SCENE] [SECONDS]
set -e
BIN=${1:-target/debug/mcmc-render}
OUT=${2:-/tmp/pathspace-rates}
SCENE=${3:-caustic-sds}
SECS=${4:-20}
mkdir -p "$OUT"
R="nice -n 5 $BIN render scenes/$SCENE.xml -D width=128 -D height=96 --time $SECS --threads 2"
echo "start $(date -u +%T) load: $(uptime | sed 's/.*load average: //')"
$R --integrator pssmlt --out "$OUT/pssmlt.exr"
$R --integrator mlt --set lens_perturbation=1 --set caustic_perturbation=1 \
  --set multi_chain_perturbation=1 --out "$OUT/mlt-mitsuba.exr"
$R --integrator mept --out "$OUT/mept.exr"
$R --integrator erpt --out "$OUT/erpt.exr"
echo "end $(date -u +%T) load: $(uptime | sed 's/.*load average: //')"
