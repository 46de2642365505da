#!/bin/sh
# Session 26 slot (18:15-18:35 UTC): main 9d23ebf, eager and lazy fused, mlt, mmlt; seeds 8-9.
cd /work/wt-fused || exit 1
export MCMC_RENDER=/tmp/fz/s26/bin-9d23ebf
O=docs/results/fused-s26
mkdir -p $O
while [ "$(date -u +%H%M%S)" -lt 181500 ]; do sleep 5; done
one() {
    if [ "$(date -u +%H%M%S)" -gt 183050 ]; then echo "skipped $* at $(date -u +%T)" >> /tmp/fz/s26/slot.log; return; fi
    echo "start $* at $(date -u +%T) load $(cat /proc/loadavg)" >> /tmp/fz/s26/slot.log
    flock /work/measure.lock nice -n -15 sh scenes/tools/fused_s22_study.sh $O 60 "$@"
    echo "end $* at $(date -u +%T) load $(cat /proc/loadavg)" >> /tmp/fz/s26/slot.log
}
echo "ab start at $(date -u +%T) load $(cat /proc/loadavg)" >> /tmp/fz/s26/slot.log
flock /work/measure.lock nice -n -15 sh scenes/tools/fused_conversion_ab.sh /tmp/fz/s26/ab $MCMC_RENDER
echo "ab end at $(date -u +%T) load $(cat /proc/loadavg)" >> /tmp/fz/s26/slot.log
one 8 door fused fused+conversion=lazy mlt mmlt
one 8 glossy fused fused+conversion=lazy mlt mmlt
one 9 door mmlt mlt fused+conversion=lazy fused
one 9 glossy mmlt mlt fused+conversion=lazy fused
echo "done at $(date -u +%T)" >> /tmp/fz/s26/slot.log
