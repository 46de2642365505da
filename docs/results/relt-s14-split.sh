#!/bin/sh
# Session 14 (docs/relt.md): RELT variants at equal mutations per pixel on
# the glass cube (or $SCENE), interleaved per seed, with the CPU time of each run.
# Usage: relt-s14-split.sh BINARY OUTDIR MPP "SEEDS" VARIANT...
# where VARIANT is NAME or NAME:key=value,key=value (passed as --set).
# Then: python3 docs/results/relt-s14-split.py REF.exr OUTDIR
set -e
bin=$1; out=$2; mpp=$3; seeds=$4; shift 4
mkdir -p "$out"
for seed in $seeds; do
  for v in "$@"; do
    name=${v%%:*}
    sets=""
    case $v in *:*) for kv in $(echo "${v#*:}" | tr ',' ' '); do sets="$sets --set $kv"; done ;; esac
    uptime > "$out/$name-s$seed.load"
    # shellcheck disable=SC2086
    /usr/bin/time -f "%U %S %e" -o "$out/$name-s$seed.time" \
      nice -n 5 "$bin" render "${SCENE:-scenes/relt-glass-cube.xml}" -D width=128 -D height=128 \
      --integrator relt --mutations-per-pixel "$mpp" --seed "$seed" --threads 2 --quiet \
      $sets --out "$out/$name-s$seed.exr"
  done
done
uptime > "$out/end.load"
