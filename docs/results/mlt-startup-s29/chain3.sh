#!/usr/bin/env bash
# Session 29: mlt (session-29 defaults) against mlt with the BDPT start-up (100 000 draws), 60 s, seed 0; A-B / B-A.
cd /work/s29/unc
export MR=/work/mr29a TAG=startup
B='mlt+bdpt_startup=true'
./slot.sh interior-window "mlt,$B"
./slot.sh door-ajar-real "$B,mlt"
./slot.sh door-ajar "mlt,$B"
./slot.sh cornell-glossy-glass "$B,mlt"
./slot.sh cornell-box "mlt,$B"
./slot.sh mirror-balls "$B,mlt"
echo done3 $(date -u +%T) >> slot.log
