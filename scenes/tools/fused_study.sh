#!/bin/sh
# Issue 18's equal-time study: fused vs mmlt vs mlt, 60 s each, 2 threads,
# side by side in one `mcmc-render convergence` run per scene, on the door
# scene (diffuse visibility, where path-space MLT should win) and the
# glossy-glass box (where MMLT should win). Writes, per scene, the CSV and
# plot of relMSE against time, and with --images each integrator's final
# image, statistics and per-pixel relative-error maps (EXR and PNG).
# `uptime` is logged before and after each scene (the machine is shared).
#
#   sh scenes/tools/fused_study.sh [OUT_DIR] [SECONDS] [SEED]
#
# Run from the repository root after
#   cargo build -p mcmc-render --profile test
# (the binary is target/debug/mcmc-render; set MCMC_RENDER to use another).
set -eu
out=${1:-fused-study}
secs=${2:-60}
seed=${3:-0}
bin=${MCMC_RENDER:-target/debug/mcmc-render}
mkdir -p "$out"
log="$out/uptime.log"
run() {
    name=$1
    shift
    echo "$name start: $(uptime)" | tee -a "$log"
    nice -n 5 "$bin" convergence "$@" --integrators fused,mmlt,mlt \
        --time "$secs" --checkpoints 6 --threads 2 --seed "$seed" \
        --out "$out/$name.csv" --images "$out/$name" | tee "$out/$name.txt"
    echo "$name end: $(uptime)" | tee -a "$log"
}
run door-ajar scenes/door-ajar.xml -D width=128 -D height=96 \
    --reference scenes/reference/door-ajar-bdpt.exr
run glossy-glass scenes/cornell-glossy-glass.xml \
    --reference scenes/reference/cornell-glossy-glass.exr
