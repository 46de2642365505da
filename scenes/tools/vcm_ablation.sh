#!/bin/sh
# The ablation of the thesis's Fig. 6.21 in small (docs/vcm.md, "Ablation
# (session 15)"): mcmc-vcm at equal work (ITERATIONS iterations each) in four
# settings, interleaved per seed (A B C D A B C D): both chains with exchanges
# and all VCM techniques (the defaults), the contribution chain only
# (light_chains=contribution), BDPT's techniques only (mode=bpt, merging off),
# and both changes. Each run logs its CPU time (/usr/bin/time: user, system,
# wall), its relMSE/RMSE against REFERENCE (`mcmc-render compare`) and the
# load (`uptime`) after it. Extra arguments (e.g. `--set radius=0.01`) go to
# every render.
#
# Usage: scenes/tools/vcm_ablation.sh BINARY SCENE REFERENCE ITERATIONS OUTDIR "SEEDS" [--set k=v ...]
set -u
BIN=$1 SCENE=$2 REF=$3 ITER=$4 OUT=$5 SEEDS=$6
shift 6
mkdir -p "$OUT"
name=$(basename "$SCENE" .xml)
echo "start $(date -u +%FT%TZ) $BIN $SCENE ${ITER} iterations extra [$*] load: $(uptime | sed 's/.*load average: //')"
for seed in $SEEDS; do
  for variant in both-vcm contribution-vcm both-bpt contribution-bpt; do
    case $variant in
      both-vcm) sets="" ;;
      contribution-vcm) sets="--set light_chains=contribution" ;;
      both-bpt) sets="--set mode=bpt" ;;
      contribution-bpt) sets="--set light_chains=contribution --set mode=bpt" ;;
    esac
    img="$OUT/$name-$variant-s$seed.exr"
    # shellcheck disable=SC2086
    /usr/bin/time -o "$OUT/time.txt" -f "user %U sys %S wall %e" "$BIN" render "$SCENE" \
      --integrator mcmc-vcm $sets "$@" --spp "$ITER" --threads 2 --seed "$seed" --out "$img" \
      >/dev/null 2>"$OUT/$name-$variant-s$seed.log"
    cpu=$(tail -1 "$OUT/time.txt")
    cmp=$("$BIN" compare "$REF" "$img" 2>&1 | tr '\n' ' ')
    echo "$variant seed $seed: $cpu | $cmp | load $(uptime | sed 's/.*load average: //')"
  done
done
echo "end $(date -u +%FT%TZ)"
