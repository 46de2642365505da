#!/usr/bin/env bash
# Session 28's equal-time slot on door-ajar (docs/smcmc.md, "Session 28"): one locked
# 60 s convergence command of INTEGRATORS (comma-separated) for SEED, run from the repo root.
#   MCMC_RENDER=target/debug/mcmc-render OUT=dir TAG=-a03 [SESSION=s31] scenes/tools/smcmc_door_slot_s28.sh SEED INTEGRATORS
# e.g. K=smcmc+shift=bdpt+init=global+init_candidates=1; SEED 13: "mmlt,$K,$K+alpha=0.5",
# 14: "$K+alpha=0.5,$K,mmlt", 15: "$K,mmlt,$K+alpha=0.5"; then "$K+alpha=0.2" and "$K+alpha=0.3" alone.
set -euo pipefail
B=${MCMC_RENDER:-target/debug/mcmc-render}; O=${OUT:-.}; S=$1; I=$2
echo "seed $S $I start $(date -u +%T) $(uptime)" >> "$O/slot.log"
flock /work/measure.lock /usr/bin/time -f "%U user %S sys %e wall" -a -o "$O/slot.log" nice -n -15 "$B" convergence scenes/door-ajar.xml \
  -D width=128 -D height=96 --reference scenes/reference/door-ajar-bdpt.exr \
  --second-reference scenes/reference/door-ajar.exr \
  --integrators "$I" --time 60 --checkpoints 4 --threads 2 --seed "$S" \
  --out "$O/door-ajar-60s-smcmc-${SESSION:-s28}-seed$S${TAG:-}.csv" --images "$O/img-$S"
echo "seed $S end $(date -u +%T) $(uptime)" >> "$O/slot.log"
