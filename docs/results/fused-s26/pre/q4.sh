#!/bin/sh
# weights among the path-space moves: door lens 9:1, glossy lens 3:1; 20 s, 2 threads, nice 10 (untimed: CPU s recorded)
cd /work/wt-fused
O=/tmp/fz/s26/q; B=/tmp/fz/s26/bin-9d23ebf
for s in 10 11 12 13; do
  for sc in door gl; do
  case $sc in
  door) v=lens_perturbation=9; args="scenes/door-ajar.xml -D width=128 -D height=96 --reference scenes/reference/door-ajar-bdpt.exr --second-reference scenes/reference/door-ajar.exr";;
  gl) v=lens_perturbation=3; args="scenes/cornell-glossy-glass.xml --reference scenes/reference/cornell-glossy-glass.exr --reference-variance scenes/reference/cornell-glossy-glass.var.exr --reference-spp 2048";;
  esac
  tag=$(echo $v | tr = _)
  echo "seed $s $sc $tag load $(cat /proc/loadavg)" >> $O/q4.log
  /usr/bin/time -a -o $O/q4.log -f "seed $s $sc $tag %U user %S sys %e wall" nice -n 10 $B convergence $args --integrators fused+$v --time 20 --checkpoints 4 --threads 2 --seed $s --out $O/$sc-s$s-$tag.csv > /dev/null 2>&1
done; done
echo done >> $O/q4.log
