#!/usr/bin/env bash
# Session 29: mlt's start-up size at 60 s: default (100 000 candidates), 2 000 000 candidates, 1 000 000 BDPT draws; seed 0.
cd /work/s29/unc
export MR=/work/mr29a TAG=boot
C='mlt+bootstrap=2000000'; B='mlt+bdpt_startup=true+bootstrap=1000000'
./slot.sh door-ajar-real "mlt,$C,$B"
./slot.sh door-ajar "$B,$C,mlt"
./slot.sh interior-window "mlt,$C,$B"
./slot.sh cornell-glossy-glass "$B,$C,mlt"
echo done4 $(date -u +%T) >> slot.log
