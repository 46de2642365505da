#!/bin/sh
# Runs one fuzz target for SECONDS (default 600) at low priority, in
# libFuzzer's fork mode so that a crash, hang (> 10 s) or out-of-memory
# (> 2 GB) is saved in fuzz/artifacts/TARGET/ and the run goes on. New
# inputs go to fuzz/corpus/TARGET (not committed); fuzz/seeds/TARGET is the
# committed seed corpus. Build first (once for all targets):
#   cargo +nightly fuzz build -s none --debug-assertions
# Usage (from mcmc-render/): fuzz/run.sh TARGET [SECONDS] [WORKERS]
# WORKERS (default 1) fuzzing processes run at once (libFuzzer's -fork=N):
# 2 uses both cores of the 2-core machine.
# FUZZ_BIN_DIR=DIR runs DIR/TARGET instead of the build's binary (a copy,
# so that a rebuild during a run does not swap the binary that libFuzzer's
# fork mode re-executes for every job).
# FUZZ_NICE=N runs at niceness N instead of 10 (0: an equal share with
# everything else on the machine).
set -e
target=$1
seconds=${2:-600}
workers=${3:-1}
bin=${FUZZ_BIN_DIR:-fuzz/target/x86_64-unknown-linux-gnu/release}/$target
mkdir -p fuzz/corpus/$target fuzz/artifacts/$target
exec nice -n "${FUZZ_NICE:-10}" "$bin" fuzz/corpus/$target fuzz/seeds/$target \
    -fork=$workers -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
    -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
    -max_total_time=$seconds -artifact_prefix=fuzz/artifacts/$target/
