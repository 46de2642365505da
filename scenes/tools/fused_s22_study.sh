#!/bin/sh
# Session 22: issue 18's 60 s study, corrected errors. One `convergence`
# command per integrator (so that /usr/bin/time gives each one's CPU
# seconds), in the order given; the load (/proc/loadavg) before and after
# each in OUT_DIR/SCENE-seedSEED.log.
#
#   flock /work/measure.lock nice -n -15 \
#     sh scenes/tools/fused_s22_study.sh OUT_DIR SECONDS SEED door|glossy INTEGRATOR...
#
# door: door-ajar at 128x96 against two independent references (the BDPT
# one and Mitsuba's, --second-reference); glossy: cornell-glossy-glass
# against Mitsuba's 2048-spp reference with its variance image (16 seeds
# x 16 spp, scenes/reference/cornell-glossy-glass.var.exr).
# Run from the repository root; MCMC_RENDER names the binary (default
# target/debug/mcmc-render, built with --profile test).
set -eu
out=$1
secs=$2
seed=$3
which=$4
shift 4
bin=${MCMC_RENDER:-target/debug/mcmc-render}
mkdir -p "$out"
case $which in
door)
    name=door-ajar
    set -- "$@" --
    args="scenes/door-ajar.xml -D width=128 -D height=96 --reference scenes/reference/door-ajar-bdpt.exr --second-reference scenes/reference/door-ajar.exr"
    ;;
glossy)
    name=glossy-glass
    set -- "$@" --
    args="scenes/cornell-glossy-glass.xml --reference scenes/reference/cornell-glossy-glass.exr --reference-variance scenes/reference/cornell-glossy-glass.var.exr --reference-spp 2048"
    ;;
*)
    echo "usage: $0 OUT_DIR SECONDS SEED door|glossy INTEGRATOR..." >&2
    exit 2
    ;;
esac
log="$out/$name-seed$seed.log"
for integ in "$@"; do
    [ "$integ" = -- ] && break
    tag=$(echo "$integ" | tr '+=' '__')
    echo "$name $integ seed $seed start: load $(cat /proc/loadavg) at $(date -u +%T)" >> "$log"
    # shellcheck disable=SC2086
    /usr/bin/time -f "$name $integ seed $seed: %e s wall, %U s user, %S s sys" -a -o "$log" \
        "$bin" convergence $args --integrators "$integ" --time "$secs" --checkpoints 4 \
        --threads 2 --seed "$seed" --out "$out/$name-seed$seed-$tag.csv" \
        --images "$out/$name-seed$seed-$tag" > /dev/null
    echo "$name $integ seed $seed end: load $(cat /proc/loadavg) at $(date -u +%T)" >> "$log"
done
