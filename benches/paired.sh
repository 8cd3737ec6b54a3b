#!/usr/bin/env bash
# Paired whole-process timing, with public tools only (bash, taskset, sort, awk): runs command A
# and command B in turn, A B A B …, and prints each one's wall seconds and the pair-by-pair
# ratio A/B as min, median and max, and how many pairs A won. Pairing keeps a ratio meaningful
# when the machine's speed drifts during the run (a VM's neighbours); quote the median.
#
#   benches/paired.sh RUNS 'COMMAND_B' COMMAND_A [ARG …]
#   PIN=1 benches/paired.sh 30 'mbtap-old replay pf.pcapng --format summary' \
#       mbtap replay pf.pcapng --format summary
#
# COMMAND_B is one string split as a shell splits words (no pipes); both commands' output is
# thrown away. One warm-up run of each is not counted. PIN=N runs both on processor N.
set -euo pipefail

if [ $# -lt 3 ]; then
    echo "usage: $0 RUNS 'COMMAND_B' COMMAND_A [ARG ...]" >&2
    exit 2
fi
runs=$1
read -r -a b <<<"$2"
shift 2
a=("$@")
pin=()
if [ -n "${PIN:-}" ]; then
    pin=(taskset -c "$PIN")
fi

# Wall seconds of one run, from bash's microsecond clock around the child.
wall() {
    local t0=$EPOCHREALTIME
    "${pin[@]}" "$@" >/dev/null 2>&1 </dev/null || echo "paired.sh: exit $? from: $*" >&2
    local t1=$EPOCHREALTIME
    awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.6f\n", b - a }'
}

wall "${a[@]}" >/dev/null
wall "${b[@]}" >/dev/null
rows=$(mktemp)
trap 'rm -f "$rows"' EXIT
for _ in $(seq "$runs"); do
    ta=$(wall "${a[@]}")
    tb=$(wall "${b[@]}")
    echo "$ta $tb" >>"$rows"
done

# min, median, max of one column of numbers on stdin.
stats() {
    sort -g | awk '{ v[NR] = $1 } END {
        m = (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2
        printf "%10.4f %10.4f %10.4f\n", v[1], m, v[NR] }'
}
printf '%-10s %10s %10s %10s\n' "" min median max
printf '%-10s %s\n' "A wall s" "$(awk '{ print $1 }' "$rows" | stats)"
printf '%-10s %s\n' "B wall s" "$(awk '{ print $2 }' "$rows" | stats)"
printf '%-10s %s\n' "A/B wall" "$(awk '{ print $1 / $2 }' "$rows" | stats)"
awk '$1 < $2 { w++ } END { printf "A faster in %d of %d pairs\n", w, NR }' "$rows"
