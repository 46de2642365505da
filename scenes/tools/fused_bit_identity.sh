#!/bin/sh
# Session 20: fixed-seed renders for checking that a change keeps images
# bit-identical (compare two binaries' outputs with `cmp` of the EXRs and
# the JSONs' image_hash).
#
#   sh scenes/tools/fused_bit_identity.sh BINARY OUT_DIR TAG
#
# Run from the repository root.
set -eu
b=$1
o=$2
t=$3
mkdir -p "$o"
r() {
    name=$1
    shift
    nice -n 10 "$b" render "$@" --seed 5 --out "$o/$t-$name.exr" > "$o/$t-$name.log" 2>&1
}
r fused-door scenes/door-ajar.xml -D width=96 -D height=72 --integrator fused --mutations-per-pixel 24 --threads 2
r fused05-glossy scenes/cornell-glossy-glass.xml -D width=64 -D height=64 --integrator fused --set path_space_probability=0.5 --mutations-per-pixel 24 --threads 2
r fused-glossy scenes/cornell-glossy-glass.xml -D width=64 -D height=64 --integrator fused --mutations-per-pixel 24 --threads 1
r mlt-door scenes/door-ajar.xml -D width=96 -D height=72 --integrator mlt --mutations-per-pixel 24 --threads 2
r mmlt-glossy scenes/cornell-glossy-glass.xml -D width=64 -D height=64 --integrator mmlt --mutations-per-pixel 24 --threads 2
r fused-sky scenes/envmap-spheres.xml -D width=48 -D height=36 --integrator fused --max-depth 5 --mutations-per-pixel 24 --threads 2
