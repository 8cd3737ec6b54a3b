#!/usr/bin/env bash
# Does the sniffer lose frames on a busy live line? `mbtap simulate` at 115200 8N1 on a pseudo-terminal,
# `mbtap tap` in front of it, and a pymodbus master polling through the tap as fast as the devices
# answer for SECONDS (default 300). Compares what the master counted with what mbtap heard.
# Needs python3 with pymodbus. Usage: benches/pty_no_loss.sh [SECONDS]
set -euo pipefail
seconds="${1:-300}"
bin="$(dirname "$0")/../target/release/mbtap"
dir="$(mktemp -d)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$dir"' EXIT
"$bin" simulate --link "$dir/bus" --baud 115200 --parity none --duration $((seconds + 30)) 2>/dev/null &
while [ ! -e "$dir/bus" ]; do sleep 0.1; done
"$bin" tap "$dir/bus" --link "$dir/app" --baud 115200 --parity none --format jsonl --duration $((seconds + 20)) \
  > "$dir/tap.jsonl" 2>/dev/null &
tap=$!
while [ ! -e "$dir/app" ]; do sleep 0.1; done
python3 "$(dirname "$0")/poll_loop.py" "$dir/app" "$seconds"
kill -INT "$tap"; wait "$tap" || true
tail -n 1 "$dir/tap.jsonl"
