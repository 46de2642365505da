#!/bin/sh
# Issue #15's equal-time study: on the Ring, Mirror-balls and Glass-knot scenes (in the
# spirit of the thesis's, seed 000 §5.5), tempered replica exchange
# (PSSMLT and MMLT variants, and tempered-PSSMLT with a decaying
# regularisation in stages) against PSSMLT over BDPT, MMLT, MEPT and PT,
# side by side in ONE `convergence` run per scene, so the machine's load
# hits them alike. References: Mitsuba 3 (scenes/reference/SCENE.exr, made
# by scenes/tools/mitsuba_reference.py, see scenes/README.md).
# Runs under nice -n 5; `uptime` is logged before and after every scene.
#
# Usage: scenes/tools/tempered_study.sh BINARY OUTDIR [SECONDS]
#   BINARY   e.g. target/debug/mcmc-render (built with --profile test)
#   SECONDS  per integrator (default 120)
# SCENES, LIST, SEED (environment, optional): other scenes, other
# integrators, another seed (default 7; the CSV is then tempered-SCENE-sSEED.csv).
# Output: OUTDIR/tempered-SCENE.csv (+ .png), OUTDIR/tempered-SCENE/ (final
# images, sidecars, error maps) and OUTDIR/tempered-study.log.
set -u
BIN=${1:-target/debug/mcmc-render}
OUT=${2:-docs/results}
SECS=${3:-120}
SEED=${SEED:-7}
TAG=$([ "$SEED" = 7 ] || echo "-s$SEED")
LOG="$OUT/tempered-study.log"
mkdir -p "$OUT"
LIST=${LIST:-pt,pssmlt-bdpt,mmlt,mept,tempered-pssmlt,tempered-mmlt,tempered-pssmlt+regularization=power+rho0=0.02+gamma=0.5+regularization_stages=5}
for s in ${SCENES:-ring mirror-balls glass-knot}; do
  echo "$s seed $SEED $SECS s [$LIST] start $(date -u +%T) load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
  nice -n 5 "$BIN" convergence "scenes/$s.xml" --reference "scenes/reference/$s.exr" \
    --integrators "$LIST" --time "$SECS" --checkpoints 8 --seed "$SEED" \
    --out "$OUT/tempered-$s$TAG.csv" --images "$OUT/tempered-$s$TAG" >> "$LOG" 2>&1
  echo "$s end $(date -u +%T) rc $? load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
done
