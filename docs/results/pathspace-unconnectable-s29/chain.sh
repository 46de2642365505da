#!/usr/bin/env bash
# Session 29: mlt against mlt+U20 at 60 s, seed 0, on the Dirac-lobe scenes; A-B / B-A.
cd /work/s29/unc
export MR=/work/mr28b
U='mlt+unconnectable_pass=true+specular_time_share=0.2'
./slot.sh cornell-glossy-glass "mlt,$U"
./slot.sh interior-window "$U,mlt"
./slot.sh mirror-balls "mlt,$U"
./slot.sh smallvcm-box "$U,mlt"
./slot.sh cornell-plastic "mlt,$U"
./slot.sh cornell-thindielectric "$U,mlt"
./slot.sh door-ajar-real "mlt,$U"
echo done $(date -u +%T) >> slot.log
