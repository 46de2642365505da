#!/bin/sh
# issue 14: 60 s goal runs with relt's filmed normalisation (branch s24-relt 061fdf8 binary)
cd "$(dirname "$0")/../.."
BIN=${MCMC_RENDER:-target/debug/mcmc-render}
OUT=${OUT:-relt-goal}
mkdir -p $OUT
run() { # scene seed list
  echo "$1 seed $2 start $(date -u +%T) load $(cat /proc/loadavg)" >> $OUT/log
  flock /work/measure.lock nice -n -15 /usr/bin/time -f "$1 seed $2: %e s wall, %U s user, %S s sys" -a -o $OUT/log \
    $BIN convergence scenes/relt-$1.xml -D width=128 -D height=128 --reference scenes/reference/relt-$1.exr \
    --reference-variance scenes/reference/relt-$1.var.exr --reference-spp 6016 \
    --integrators $3 --time 60 --checkpoints 6 --threads 2 --seed $2 \
    --images $OUT/img-$1-s$2 --out $OUT/relt-s24-$1-goal-s$2.csv > /dev/null
  echo "$1 seed $2 end $(date -u +%T) load $(cat /proc/loadavg)" >> $OUT/log
}
A=relt+normalization=filmed,bdpt,pssmlt-bdpt,mmlt,mlt
B=mlt,mmlt,pssmlt-bdpt,bdpt,relt+normalization=filmed
run water-box 4 $A
run water-box 5 $B
run glass-cube 2 $A
echo done > $OUT/done
