#!/usr/bin/env bash
# run.sh VARIANT SEED: one tempered-pssmlt render of mirror-balls (session 28 bias split)
set -e
M=.; v=$1; s=$2   # from the repo root
case $v in
  off) SET="--set regularization=off";;
  constant) SET="--set regularization=constant";;
  power4) SET="--set regularization=power --set gamma=0.5 --set regularization_stages=4";;
esac
/usr/bin/time -f "%U %S" -o reg-$v-$s.time nice -n 15 mcmc-render render $M/scenes/mirror-balls.xml --integrator tempered-pssmlt $SET \
  --mutations-per-pixel 512 --threads 1 --seed $s --quiet --out reg-$v-$s.exr
rm -f reg-$v-$s.png
