#!/bin/sh
# Equal-time tables of issue #13: on every scene of scenes/ that has a
# reference, the existing integrators (pt, bdpt, pssmlt, mmlt) and the
# path-space ones (mlt, mept, erpt) side by side in ONE `convergence` run
# per scene, so the machine's load hits them alike. A path-space integrator
# that refuses the scene (emitters at infinity) would abort the whole study,
# so each one is first probed with a 1 s render; a refusal is logged with
# its message and the integrator is left out of that scene's study.
# Runs under nice -n 5; `uptime` is logged before and after every scene.
#
# Usage: scenes/tools/path_space_equal_time.sh BINARY OUTDIR [SECONDS_HARD] [SECONDS_OTHER]
#   SECONDS_HARD (default 60): door-ajar and caustic-sds, the scenes with goals;
#   SECONDS_OTHER (default 60): every other scene.
# SCENES (environment, optional): only these scenes, each at SECONDS_OTHER
# (door-ajar and caustic-sds at SECONDS_HARD), e.g.
#   SCENES="door-ajar-real cornell-box" scenes/tools/path_space_equal_time.sh BIN docs/results 60 60
# Output: OUTDIR/pathspace-SCENE.csv (+ .png) and OUTDIR/pathspace-equal-time.log.
set -u
BIN=${1:-target/debug/mcmc-render}
OUT=${2:-docs/results}
HARD=${3:-60}
OTHER=${4:-60}
LOG="$OUT/pathspace-equal-time.log"
mkdir -p "$OUT"
echo "start $(date -u +%FT%TZ) binary $BIN" >> "$LOG"

# scene  reference  extra defines  seconds
run_scene() {
  name=$1; ref=$2; defs=$3; secs=$4
  list=pt,bdpt,pssmlt,mmlt
  for i in mlt mept erpt; do
    msg=$(nice -n 5 "$BIN" render "scenes/$name.xml" $defs \
      --integrator "$i" --time 1 --threads 2 --out "/tmp/pathspace-probe-$i.exr" 2>&1 >/dev/null)
    if [ $? -eq 0 ]; then
      list="$list,$i"
    else
      echo "$name $i refuses: $(echo "$msg" | tail -1)" >> "$LOG"
    fi
  done
  echo "$name $secs s [$list] start $(date -u +%T) load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
  nice -n 5 "$BIN" convergence "scenes/$name.xml" $defs --reference "scenes/reference/$ref.exr" \
    --integrators "$list" --time "$secs" --checkpoints 5 --threads 2 \
    --out "$OUT/pathspace-$name.csv" >> "$LOG" 2>&1
  echo "$name end $(date -u +%T) rc $? load: $(uptime | sed 's/.*load average: //')" >> "$LOG"
}

# The door scenes and caustic-sds render at 128x96, as their references.
small="-D width=128 -D height=96"
for s in ${SCENES:-door-ajar caustic-sds cornell-box cornell-glossy-glass door-ajar-real \
         cornell-plastic cornell-roughplastic cornell-thindielectric spot-floor textured \
         dof-spheres env-textured-plastic envmap-spheres mask-leaves normalmap-bumpmap \
         textured-roughness}; do
  case $s in
    door-ajar) run_scene door-ajar door-ajar-bdpt "$small" "$HARD" ;;
    caustic-sds) run_scene caustic-sds caustic-sds "$small" "$HARD" ;;
    door-ajar-real) run_scene door-ajar-real door-ajar-real "$small" "$OTHER" ;;
    *) run_scene "$s" "$s" "" "$OTHER" ;;
  esac
done
echo "done $(date -u +%FT%TZ)" >> "$LOG"
