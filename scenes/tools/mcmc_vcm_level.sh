#!/bin/sh
# The image level of mcmc-vcm over seeds (docs/vcm.md, "Session 16: the
# two-chain level error"): per seed, one render of ITERATIONS iterations
# (equal work), its image-mean deviation and RMSE against REFERENCE
# (`mcmc-render compare`), and from the JSON sidecar b_vis and the b_con
# estimates (direct, visibility, transfer) with their relative standard
# errors and the MIS scale k; CPU = user and system seconds of the render.
# Extra arguments (e.g. `--set radius=0.01 --set con_estimate=direct`) go
# to every render.
#
# Usage: scenes/tools/mcmc_vcm_level.sh BINARY SCENE REFERENCE ITERATIONS OUTDIR "SEEDS" [--set k=v ...]
set -u
BIN=$1 SCENE=$2 REF=$3 ITER=$4 OUT=$5 SEEDS=$6
shift 6
mkdir -p "$OUT"
echo "start $(date -u +%T) load $(uptime | sed 's/.*load average: //') extra [$*]"
for s in $SEEDS; do
  /usr/bin/time -o "$OUT/time.txt" -f "%U %S" "$BIN" render "$SCENE" --integrator mcmc-vcm "$@" \
    --spp "$ITER" --threads 2 --seed "$s" --out "$OUT/s$s.exr" >/dev/null 2>&1
  cmp=$("$BIN" compare "$REF" "$OUT/s$s.exr")
  g=$(echo "$cmp" | awk '/^mean rel/{print $5}')
  rmse=$(echo "$cmp" | awk '/^RMSE/{print $2}')
  stats=$(python3 - "$OUT/s$s.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
def est(key):
    v, se = d.get(key), d.get(key + "_standard_error")
    if v is None or se is None or v == 0:
        return "%s -" % key
    return "%s %.5e ± %.2f%%" % (key, v, 100 * se / v)
print(" | ".join([est("b_vis"), est("b_con_direct"), est("b_con_visibility"),
                  est("b_con_transfer"), "k %.1f" % d["light_density_scale"]]))
PY
)
  echo "seed $s G $g RMSE $rmse | $stats | cpu $(cat "$OUT/time.txt")"
done
echo "end $(date -u +%T) load $(uptime | sed 's/.*load average: //')"
