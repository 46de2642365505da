#!/bin/sh
# door: fixed path_space_probability 0.2 (lens 1:1), and mmlt; 20 s, 2 threads, nice 10 (untimed: CPU s recorded)
cd /work/wt-fused
O=/tmp/fz/s26/q; B=/tmp/fz/s26/bin-9d23ebf
for s in 10 11 12 13; do for v in fused+path_space_probability=0.2 mmlt; do
  tag=$(echo $v | tr = _)
  echo "seed $s door $tag load $(cat /proc/loadavg)" >> $O/q6.log
  /usr/bin/time -a -o $O/q6.log -f "seed $s door $tag %U user %S sys %e wall" nice -n 10 $B convergence scenes/door-ajar.xml -D width=128 -D height=96 --reference scenes/reference/door-ajar-bdpt.exr --second-reference scenes/reference/door-ajar.exr --integrators $v --time 20 --checkpoints 4 --threads 2 --seed $s --out $O/door-s$s-$tag.csv --images $O/door-s$s-$tag > /dev/null 2>&1
done; done
echo done >> $O/q6.log
