#!/bin/sh
# Session 20: CPU time of fused before and after a change for the same
# work, alternated, beside mlt and mmlt (user seconds from /usr/bin/time;
# 150 mutations per pixel at 128x96, 20 000 candidates, 1 thread, seed 3).
#
#   BEFORE=old-binary AFTER=new-binary sh scenes/tools/fused_cost_ab.sh OUT_DIR
#
# Run from the repository root.
set -eu
o=$1
mkdir -p "$o"
log=$o/ab.log
one() {
    tag=$1
    bin=$2
    integ=$3
    shift 3
    echo "$tag start: $(uptime)" >> "$log"
    /usr/bin/time -f "$tag: %e s wall, %U s user, %S s sys" -a -o "$log" nice -n 5 "$bin" render "$@" \
        --integrator "$integ" --mutations-per-pixel 150 --bootstrap 20000 --threads 1 --seed 3 \
        --out "$o/$tag.exr" >> "$log" 2>&1
}
door="scenes/door-ajar.xml -D width=128 -D height=96"
glossy="scenes/cornell-glossy-glass.xml -D width=128 -D height=96"
for r in 1 2; do
    # shellcheck disable=SC2086
    one door-fused-before$r "$BEFORE" fused $door
    # shellcheck disable=SC2086
    one door-fused-after$r "$AFTER" fused $door
done
# shellcheck disable=SC2086
one door-mlt "$AFTER" mlt $door
# shellcheck disable=SC2086
one door-mmlt "$AFTER" mmlt $door
for r in 1 2; do
    # shellcheck disable=SC2086
    one glossy-fused-before$r "$BEFORE" fused $glossy
    # shellcheck disable=SC2086
    one glossy-fused-after$r "$AFTER" fused $glossy
done
# shellcheck disable=SC2086
one glossy-mmlt "$AFTER" mmlt $glossy
echo "end: $(uptime)" >> "$log"
