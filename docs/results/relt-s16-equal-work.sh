#!/bin/sh
# Session 16 (relt): equal work on the water box, 128x128, 64 mutations per pixel, 2 threads, nice 15, no lock.
cd /work/wt-relt
B=/tmp/relt-mr
O=/tmp/relt16/ew
mkdir -p $O
for seed in 1 2; do
  for v in "A l0_search=1000000 l0_search_rate=0" "B l0_search=1000000 l0_search_rate=1" "C l0_search=4000000 l0_search_rate=0"; do
    set -- $v
    echo "$1 s$seed start $(date -u +%T) $(uptime)" >> $O/load
    /usr/bin/time -f "%U %S %e" -o $O/$1-s$seed.time nice -n 15 $B render scenes/relt-water-box.xml -D width=128 -D height=128 \
      --integrator relt --set $2 --set $3 --mutations-per-pixel 64 --seed $seed --threads 2 --quiet --out $O/$1-s$seed.exr
    $B compare --json /tmp/relt/ref-water.exr $O/$1-s$seed.exr > $O/$1-s$seed.cmp
  done
done
echo "end $(date -u +%T) $(uptime)" >> $O/load
