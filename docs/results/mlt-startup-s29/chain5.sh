#!/usr/bin/env bash
# Session 29: mlt's start-up size, more scenes and seeds: default (100 000 candidates) against 2 000 000; A-B / B-A.
cd /work/s29/unc
export MR=/work/mr29a TAG=boot
C='mlt+bootstrap=2000000'
./slot.sh interior-window "$C,mlt" 1
./slot.sh door-ajar-real "$C,mlt" 1
./slot.sh mirror-balls "mlt,$C"
./slot.sh smallvcm-box "$C,mlt"
echo done5 $(date -u +%T) >> slot.log
