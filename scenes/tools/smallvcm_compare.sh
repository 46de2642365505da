#!/bin/bash
# Side-by-side comparison of our `vcm` with SmallVCM's `vcm` on SmallVCM's own
# Cornell box (scenes/smallvcm-box.xml = its Scene::kDefault), issue #16.
#
# SmallVCM's code stays out of this repository: this script clones it into a
# scratch directory and changes five places there:
#   - its scene table gains its own Scene::kDefault box (its four command-line
#     scenes all have a modified-Phong glossy floor, which we do not model);
#   - `-o x.pfm` is accepted and written (its PFM writer exists; nothing called it);
#   - the resolution is $RES x $RES instead of 512 x 512;
#   - it prints how many iterations it ran.
# Its `-t` budget is process CPU time (clock()), so the runs are matched in CPU
# seconds: ours runs for T s of wall time, SmallVCM then for the CPU seconds
# ours used (measured by /usr/bin/time). Run it under the measurement lock.
#
# Usage: scenes/tools/smallvcm_compare.sh MCMC_RENDER WORKDIR [T=60] [SEED=1] [RES=256]
# (SMALLVCM_GIT=URL-or-path overrides where SmallVCM is cloned from.)
# Then: python3 scenes/tools/smallvcm_rmse.py REFERENCE.exr WORKDIR/eq-ours-SEED.exr WORKDIR/eq-svcm-SEED.pfm
set -euo pipefail
BIN=$(realpath "$1"); WORK=$(realpath -m "$2"); T=${3:-60}; S=${4:-1}; RES=${5:-256}
SCENES=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$WORK"
SV="$WORK/smallvcm"
if [ ! -x "$SV/smallvcm" ]; then
  [ -d "$SV" ] || git clone -q "${SMALLVCM_GIT:-https://github.com/SmallVCM/SmallVCM}" "$SV"
  git -C "$SV" checkout -q a13690f
  sed -i 's/^    Scene::kGlossyFloor | Scene::kBothSmallSpheres  | Scene::kLightBackground$/&,\n    Scene::kDefault/' "$SV/src/config.hxx"
  sed -i 's/if(extension != ".bmp" \&\& extension != ".hdr")/if(extension != ".bmp" \&\& extension != ".hdr" \&\& extension != ".pfm")/' "$SV/src/config.hxx"
  sed -i "s/oConfig.mResolution    = Vec2i(512, 512);/oConfig.mResolution    = Vec2i($RES, $RES);/" "$SV/src/config.hxx"
  perl -0pi -e 's/        fbuffer.SaveHDR\(config.mOutputName.c_str\(\)\);\n    else\n/        fbuffer.SaveHDR(config.mOutputName.c_str());\n    else if(extension == "pfm")\n        fbuffer.SavePFM(config.mOutputName.c_str());\n    else\n/' "$SV/src/smallvcm.cxx"
  perl -0pi -e 's/    float time = render\(config\);\n    printf\("done in %.2f s\\n", time\);/    int usedIterations = 0;\n    float time = render(config, &usedIterations);\n    printf("done in %.2f s, %d iterations (SmallVCM counts one more than it ran)\\n", time, usedIterations);/' "$SV/src/smallvcm.cxx"
  grep -q "Scene::kDefault" "$SV/src/config.hxx"
  grep -q "usedIterations" "$SV/src/smallvcm.cxx"
  grep -q "SavePFM(config" "$SV/src/smallvcm.cxx"
  (cd "$SV" && g++ -o smallvcm ./src/smallvcm.cxx -O3 -std=c++0x -fopenmp)
fi
uptime
cd "$SCENES"
/usr/bin/time -o "$WORK/ours-$S.time" -f "%e %U %S" nice -n 5 "$BIN" render smallvcm-box.xml \
  -D width=$RES -D height=$RES --integrator vcm --time "$T" --spp 1000000 --threads 2 --seed "$S" \
  --quiet --out "$WORK/eq-ours-$S.exr"
read -r W U SYS < "$WORK/ours-$S.time"
CPU=$(python3 -c "print(round($U + $SYS, 2))")
echo "ours: $W s wall, $CPU s CPU, $(python3 -c "import json; print(json.load(open('$WORK/eq-ours-$S.json'))['iterations'])") iterations"
cd "$WORK"
/usr/bin/time -o "$WORK/svcm-$S.time" -f "%e %U %S" nice -n 5 env OMP_NUM_THREADS=2 \
  "$SV/smallvcm" -s 4 -a vcm -t "$CPU" -o "$WORK/eq-svcm-$S.pfm" | tail -1
read -r W U SYS < "$WORK/svcm-$S.time"
echo "SmallVCM: $W s wall, $(python3 -c "print(round($U + $SYS, 2))") s CPU"
uptime
