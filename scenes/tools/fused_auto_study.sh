#!/bin/sh
# Session 19: fused with path_space_probability=0.5 (the default) and
# =auto beside mmlt and mlt, on the door and the glossy-glass box, one
# `convergence` command per integrator (so that /usr/bin/time gives each
# one's CPU seconds), interleaved per scene; `uptime` before each.
#
#   sh scenes/tools/fused_auto_study.sh OUT_DIR SECONDS SEED
#
# Run from the repository root; MCMC_RENDER names the binary
# (default target/debug/mcmc-render, built with --profile test).
set -eu
out=$1
secs=$2
seed=$3
bin=${MCMC_RENDER:-target/debug/mcmc-render}
mkdir -p "$out"
log="$out/seed$seed.log"
one() {
    scene=$1
    integ=$2
    shift 2
    tag=$(echo "$integ" | tr '+=' '__')
    echo "$scene $integ seed $seed start: $(uptime)" >> "$log"
    /usr/bin/time -f "$scene $integ seed $seed: %e s wall, %U s user, %S s sys" -a -o "$log" \
        "$bin" convergence "$@" --integrators "$integ" --time "$secs" --checkpoints 4 \
        --threads 2 --seed "$seed" --out "$out/$scene-seed$seed-$tag.csv" \
        --images "$out/$scene-seed$seed-$tag" > /dev/null
}
for integ in fused fused+path_space_probability=auto mmlt mlt; do
    one door-ajar "$integ" scenes/door-ajar.xml -D width=128 -D height=96 \
        --reference scenes/reference/door-ajar-bdpt.exr
done
for integ in fused fused+path_space_probability=auto mmlt mlt; do
    one glossy-glass "$integ" scenes/cornell-glossy-glass.xml \
        --reference scenes/reference/cornell-glossy-glass.exr
done
echo "end: $(uptime)" >> "$log"
