#!/usr/bin/env bash
# Session 29: mlt's new defaults (unconnectable pass, 2 000 000 candidates) against the session-28 defaults
# spelled out, one binary (main 1050da6), 60 s, seed 2; A-B / B-A.
cd /work/s29/unc
export MR=/work/mr29c TAG=defaults
O='mlt+unconnectable_pass=false+specular_time_share=0.05+bootstrap=100000'
./slot.sh interior-window "mlt,$O" 2
./slot.sh mirror-balls "$O,mlt" 2
./slot.sh door-ajar "mlt,$O" 2
./slot.sh cornell-glossy-glass "$O,mlt" 2
echo done6 $(date -u +%T) >> slot.log
