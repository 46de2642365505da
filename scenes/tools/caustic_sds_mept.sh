#!/bin/sh
# Equal-time study on scenes/caustic-sds.xml (issue #13): every integrator
# 60 s, 2 threads, one after the other in one command so that the machine's
# load hits them alike; relMSE against the committed reference.
# Usage: scenes/tools/caustic_sds_mept.sh BINARY OUT.csv
set -e
BIN=${1:-target/debug/mcmc-render}
OUT=${2:-caustic-sds-mept.csv}
uptime
nice -n 5 "$BIN" convergence scenes/caustic-sds.xml -D width=128 -D height=96 \
  --reference scenes/reference/caustic-sds.exr \
  --integrators pt,bdpt,pssmlt,mmlt,mlt,mept,erpt \
  --time 60 --checkpoints 5 --threads 2 --out "$OUT"
uptime
