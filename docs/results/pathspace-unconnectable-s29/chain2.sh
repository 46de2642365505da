#!/usr/bin/env bash
# Session 29: a second seed on the four scenes where mlt+U20's relMSE was within 2x of mlt's; B-A / A-B.
cd /work/s29/unc
export MR=/work/mr28b
U='mlt+unconnectable_pass=true+specular_time_share=0.2'
./slot.sh interior-window "mlt,$U" 1
./slot.sh door-ajar-real "$U,mlt" 1
./slot.sh cornell-glossy-glass "$U,mlt" 1
./slot.sh cornell-plastic "$U,mlt" 1
echo done2 $(date -u +%T) >> slot.log
