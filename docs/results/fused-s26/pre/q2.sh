#!/bin/sh
# door (and glossy): eager auto (main) vs eager with a lazy-run pilot (experiment binary) vs lazy (main); 20 s, 2 threads, nice 10 (untimed: CPU s recorded)
cd /work/wt-fused
O=/tmp/fz/s26/q
run() { # seed scene tag bin integrator
  s=$1; sc=$2; tag=$3; bin=$4; i=$5
  case $sc in
  door) args="scenes/door-ajar.xml -D width=128 -D height=96 --reference scenes/reference/door-ajar-bdpt.exr --second-reference scenes/reference/door-ajar.exr";;
  gl) args="scenes/cornell-glossy-glass.xml --reference scenes/reference/cornell-glossy-glass.exr --reference-variance scenes/reference/cornell-glossy-glass.var.exr --reference-spp 2048";;
  esac
  echo "seed $s $sc $tag load $(cat /proc/loadavg)" >> $O/q2.log
  /usr/bin/time -a -o $O/q2.log -f "seed $s $sc $tag %U user %S sys %e wall" nice -n 10 $bin convergence $args --integrators $i --time 20 --checkpoints 4 --threads 2 --seed $s --out $O/$sc-s$s-$tag.csv > /dev/null 2>&1
}
for s in 10 11 12 13; do
  run $s door auto /tmp/fz/s26/bin-9d23ebf fused
  run $s door pilotlazy /tmp/fz/s26/bin-pilotlazy fused
  run $s door lazy /tmp/fz/s26/bin-9d23ebf fused+conversion=lazy
done
for s in 10 11 12 13; do run $s gl pilotlazy /tmp/fz/s26/bin-pilotlazy fused; done
echo done >> $O/q2.log
