#!/bin/sh
# glossy: eager auto vs fixed 0.05 (≈ auto's choice at depths >= 3, but 0.05 at depth 1), 20 s, 2 threads, nice 10 (untimed: CPU s recorded)
cd /work/wt-fused
B=/tmp/fz/s26/bin-9d23ebf; O=/tmp/fz/s26/q
for s in 10 11 12 13; do for i in fused fused+path_space_probability=0.05; do
  tag=$(echo $i | tr '+=' '__')
  echo "seed $s $i load $(cat /proc/loadavg)" >> $O/q.log
  /usr/bin/time -a -o $O/q.log -f "seed $s $i %U user %S sys %e wall" nice -n 10 $B convergence scenes/cornell-glossy-glass.xml --reference scenes/reference/cornell-glossy-glass.exr --reference-variance scenes/reference/cornell-glossy-glass.var.exr --reference-spp 2048 --integrators $i --time 20 --checkpoints 4 --threads 2 --seed $s --out $O/gl-s$s-$tag.csv --images $O/gl-s$s-$tag > /dev/null 2>&1
done; done
echo done >> $O/q.log
