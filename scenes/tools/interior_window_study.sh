#!/bin/sh
# Issue 16's measured study on scenes/interior-window.xml (docs/vcm.md):
# one `convergence` run, so the machine's load hits every integrator alike,
# of vcm, mcmc-vcm, pssmlt and mmlt, plus the ablation variants of mcmc-vcm
# (contribution chain only; BDPT techniques only, i.e. mode=bpt), each for
# SECONDS of wall-clock time, against the long BDPT reference
# scenes/reference/interior-window.exr (2048 spp; its per-sample variance
# scenes/reference/interior-window.var.exr adds the errors with the
# reference's own share taken out, docs/rendering.md). vcm and mcmc-vcm share one merge
# radius rule: RADIUS (default 0.04 m, about one pixel's footprint at the
# back wall at 128x96), fixed (alpha = 1, the thesis's setting).
# Runs under nice -n 5; `uptime` is logged before and after.
#
# A second run compares like with like on BDPT's techniques: vcm and
# mcmc-vcm (both chains; contribution chain only) with mode=bpt, and vcm
# again, under the same load.
#
# Usage: scenes/tools/interior_window_study.sh BINARY OUTDIR [SECONDS] [RADIUS]
# Output: OUTDIR/interior-window.csv, OUTDIR/interior-window-bpt.csv (+ .png)
# and OUTDIR/interior-window.log.
set -u
BIN=${1:-target/debug/mcmc-render}
OUT=${2:-docs/results}
SECS=${3:-120}
RADIUS=${4:-0.04}
LOG="$OUT/interior-window.log"
mkdir -p "$OUT"
list="vcm,mcmc-vcm,pssmlt,mmlt,mcmc-vcm+light_chains=contribution,mcmc-vcm+mode=bpt"
echo "start $(date -u +%FT%TZ) binary $BIN ${SECS}s radius $RADIUS [$list] load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
nice -n 5 "$BIN" convergence scenes/interior-window.xml \
  --reference scenes/reference/interior-window.exr \
  --reference-variance scenes/reference/interior-window.var.exr --reference-spp 2048 \
  --integrators "$list" --set alpha=1 --set radius="$RADIUS" \
  --time "$SECS" --checkpoints 6 --threads 2 --seed 7 \
  --out "$OUT/interior-window.csv" >> "$LOG" 2>&1
echo "end $(date -u +%FT%TZ) rc $? load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
list2="vcm+mode=bpt,mcmc-vcm+mode=bpt,mcmc-vcm+mode=bpt+light_chains=contribution,vcm"
echo "start $(date -u +%FT%TZ) ${SECS}s radius $RADIUS [$list2] load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
nice -n 5 "$BIN" convergence scenes/interior-window.xml \
  --reference scenes/reference/interior-window.exr \
  --reference-variance scenes/reference/interior-window.var.exr --reference-spp 2048 \
  --integrators "$list2" --set alpha=1 --set radius="$RADIUS" \
  --time "$SECS" --checkpoints 6 --threads 2 --seed 8 \
  --out "$OUT/interior-window-bpt.csv" >> "$LOG" 2>&1
echo "end $(date -u +%FT%TZ) rc $? load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
