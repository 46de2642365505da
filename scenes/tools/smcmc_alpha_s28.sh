#!/usr/bin/env bash
# Session 28's alpha study (docs/smcmc.md, "Session 28"): one equal-work smcmc run
# and its corrected relMSE, written to OUT/SCENE-SHIFT-aALPHA-sSEED.cmp.json.
#   MCMC_RENDER=target/debug/mcmc-render OUT=dir scenes/tools/smcmc_alpha_s28.sh door|glossy|interior ALPHA SEED [SHIFT]
# The study: door seeds 3-22, glossy and interior seeds 1-6 (shift bdpt), door 3-12
# and interior 1-4 with shift rr; alpha 0.05 0.2 0.3 0.5 1 (2, 4 on door); e.g.
#   for s in $(seq 3 22); do for a in 0.05 0.3; do echo "door $a $s"; done; done | xargs -P 2 -L 1 scenes/tools/smcmc_alpha_s28.sh
set -euo pipefail
B=${MCMC_RENDER:-target/debug/mcmc-render}; O=${OUT:-.}; key=$1; a=$2; s=$3; shift_=${4:-bdpt}
R=scenes/reference
case $key in
  door) SC=(scenes/door-ajar.xml -D width=128 -D height=96); MPP=24; REF=$R/door-ajar-bdpt.exr
        CMP=(--second-reference $R/door-ajar.exr);;
  glossy) SC=(scenes/cornell-glossy-glass.xml); MPP=16; REF=$R/cornell-glossy-glass.exr
        CMP=(--reference-variance $R/cornell-glossy-glass.var.exr --reference-spp 2048);;
  interior) SC=(scenes/interior-window.xml); MPP=64; REF=$R/interior-window-pooled.exr
        CMP=(--reference-variance $R/interior-window-pooled.var.exr --reference-spp 58368);;
  *) echo "unknown scene key $key (door, glossy, interior)" >&2; exit 2;;
esac
o=$O/$key-$shift_-a$a-s$s
"$B" render "${SC[@]}" --integrator smcmc --set shift=$shift_ --set init=global --set init_candidates=1 \
  --set mutations_per_pixel=$MPP --set alpha=$a --seed $s --threads 1 --quiet --out $o.exr
"$B" compare $REF $o.exr "${CMP[@]}" --json > $o.cmp.json
rm -f $o.png
