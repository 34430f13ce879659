#!/usr/bin/env bash
# The receiver under a bounded flood (loopback only), issue #21: a default
# receiver (plaintext on 127.0.0.1, 16 sessions, 5 s Hello deadline, 30 s idle
# timeout), 50 authenticated sessions that say Hello and then nothing, 1 s
# later 300 streams that never say Hello, and at 2 s one real sender. Reports the
# receiver's threads and RSS (before, peak, at the end), how the flood's
# streams ended, when the real sender got in, and what the receiver showed.
#   bench/flood.sh OUT [--mute N] [--idle N] [--duration S]
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=${HEADCAST_BIN:-$root/build/bin}
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
command="bench/flood.sh OUT $*"
mute=300 idle=50 duration=45
while [ $# -gt 0 ]; do
  case $1 in
    --mute) mute=$2; shift 2 ;;
    --idle) idle=$2; shift 2 ;;
    --duration) duration=$2; shift 2 ;;
    *) echo "flood: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$out"
token=flood-token-0123456789
port=$((20000 + RANDOM % 20000))
"$bin/headcast-avatar" create --resolution 128 --out "$out/demo.hcavatar" > /dev/null
"$bin/headcast-receiver" --listen "127.0.0.1:$port" --plaintext --token "$token" --avatar demo="$out/demo.hcavatar" \
  --display none --duration $((duration + 5)) --json "$out/receiver.json" > /dev/null 2> "$out/receiver.log" &
rpid=$!
trap 'kill $rpid 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q listening "$out/receiver.log" && break; sleep 0.1; done
"$bin/headcast-flood" --target "127.0.0.1:$port" --token "$token" --mute "$mute" --idle "$idle" \
  --duration "$duration" --receiver-pid "$rpid" > "$out/flood.json" 2> "$out/flood.log"
wait "$rpid"
trap - EXIT
python3 - "$out" "$command" <<'PY'
import json, os, sys
out, command = sys.argv[1], sys.argv[2]
f = json.load(open(os.path.join(out, "flood.json")))
r = json.load(open(os.path.join(out, "receiver.json")))
f["command"] = command
f["receiver"] = {k: r.get(k) for k in ("sessions_started", "sessions_rejected", "hello_timeouts", "idle_timeouts", "evictions",
                                      "shown_senders", "rendered")}
json.dump(f, open(os.path.join(out, "flood_report.json"), "w"), indent=2)
print(json.dumps(f, indent=2))
PY
