#!/bin/sh
# Image means over seeds (docs/vcm.md, "Session 17"): per seed one render of
# SCENE with INTEGRATOR at SPP samples (iterations), one thread, and one line
# "seed R G B merge_share k b_con b_con_direct b_con_visibility b_con_transfer
# b_vis restart_weight_ess user_s sys_s" (the sidecar's fields; None where the
# integrator has none). Extra arguments (-D k=v, --set k=v) go to every render.
#
# Usage: scenes/tools/image_mean_reps.sh BINARY SCENE INTEGRATOR SPP OUTDIR "SEEDS" [-D k=v | --set k=v ...]
set -u
BIN=$1 SCENE=$2 INTEG=$3 SPP=$4 OUT=$5 SEEDS=$6
shift 6
mkdir -p "$OUT"
echo "# $INTEG spp $SPP [$*] start $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
for s in $SEEDS; do
  /usr/bin/time -o "$OUT/time.txt" -f "%U %S" "$BIN" render "$SCENE" --integrator "$INTEG" "$@" \
    --spp "$SPP" --seed "$s" --threads 1 --quiet --out "$OUT/s.exr" >/dev/null 2>&1 || echo "# seed $s failed"
  m=$("$BIN" compare "$OUT/s.exr" "$OUT/s.exr" | awk '/^test mean/{print $3, $4, $5}')
  x=$(python3 - "$OUT/s.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
shares = d.get("energy_shares") or {}
print(shares.get("merge", 0), *(d.get(k) for k in ("light_density_scale", "b_con", "b_con_direct",
      "b_con_visibility", "b_con_transfer", "b_vis", "restart_weight_ess")))
PY
)
  echo "$s $m $x $(cat "$OUT/time.txt")"
done
echo "# end $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
