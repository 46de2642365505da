#!/bin/sh
# Session 22: CPU time of fused with conversion=eager and =lazy for the
# same work on one binary, alternated: door at 128x96, 150 mutations per
# pixel, 20 000 candidates, 1 thread, seed 3; path_space_probability 0.5
# (the same mixture for both) and auto (each rule with its own pilot).
# User seconds from /usr/bin/time, load before each, in OUT_DIR/ab.log.
#
#   flock /work/measure.lock nice -n -15 sh scenes/tools/fused_conversion_ab.sh OUT_DIR BINARY
#
# Run from the repository root.
set -eu
o=$1; bin=$2; shift 2
mkdir -p "$o"; log=$o/ab.log
one() {
    tag=$1; shift
    echo "$tag start: $(cat /proc/loadavg)" >> "$log"
    /usr/bin/time -f "$tag: %e s wall, %U s user, %S s sys" -a -o "$log" "$bin" render \
        scenes/door-ajar.xml -D width=128 -D height=96 --integrator fused "$@" \
        --mutations-per-pixel 150 --bootstrap 20000 --threads 1 --seed 3 --out "$o/$tag.exr" >> "$log" 2>&1
}
for r in 1 2; do
    one p05-eager$r --set path_space_probability=0.5 --set conversion=eager
    one p05-lazy$r --set path_space_probability=0.5 --set conversion=lazy
    one auto-eager$r --set conversion=eager
    one auto-lazy$r --set conversion=lazy
done
echo "end: $(cat /proc/loadavg)" >> "$log"
