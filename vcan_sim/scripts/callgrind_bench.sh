#!/bin/sh
# Instructions per simulated second for each `excavator-sim bench` case, counted by callgrind (repeatable
# on a loaded machine, unlike wall time). Each case runs for 2 s and for 12 s of simulated time; the
# difference over 10 s removes start-up (config parsing, table construction).
#
#   vcan_sim/scripts/callgrind_bench.sh [path/to/excavator-sim]
set -eu
BIN=${1:-${CARGO_TARGET_DIR:-target}/release/excavator-sim}
OUT=$(mktemp -d)
for case in idle "all joints" digging node; do
    total() {
        valgrind --tool=callgrind --callgrind-out-file="$OUT/cg.out" "$BIN" bench --seconds "$1" \
            --case "$case" >/dev/null 2>"$OUT/log"
        grep -E '^summary:|^totals:' "$OUT/cg.out" | head -1 | awk '{print $2}'
    }
    short=$(total 2)
    long=$(total 12)
    echo "$case: $(( (long - short) / 10 )) instructions per simulated second"
done
rm -rf "$OUT"
