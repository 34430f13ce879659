#!/usr/bin/env bash
# A soak of the receiver (issue #21; loopback only, bounded in time): SESSIONS
# senders stream synthetic heads for MINUTES while the receiver is restarted
# every RESTART seconds (it exits at the end of its --duration; the next one
# starts a second later and the senders reconnect). Samples the receiver's RSS
# every 5 s, and at the end compares the frames the senders sent with the
# frames the receivers received, and the frames dropped with what the restart
# windows explain.
#   bench/soak.sh OUT [--minutes 30] [--sessions 8] [--restart 300]
# Writes OUT/soak.json and OUT/rss.csv; prints the summary.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=${HEADCAST_BIN:-$root/build/bin}
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
command="bench/soak.sh OUT $*"
minutes=30 sessions=8 restart=300
while [ $# -gt 0 ]; do
  case $1 in
    --minutes) minutes=$2; shift 2 ;;
    --sessions) sessions=$2; shift 2 ;;
    --restart) restart=$2; shift 2 ;;
    *) echo "soak: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$out"
rm -f "$out"/receiver_*.json "$out"/sender_*.json "$out/rss.csv"
token=soak-token-0123456789
port=$((20000 + RANDOM % 20000))
total=$((minutes * 60))
"$bin/headcast-avatar" create --resolution 128 --out "$out/demo.hcavatar" > /dev/null
pids=()
cleanup() { kill "${pids[@]}" "${rpid:-}" 2>/dev/null || true; }
trap cleanup EXIT
start=$(date +%s.%N)
elapsed() { python3 -c "import time; print(f'{time.time() - $start:.1f}')"; }
echo "t_s,run,rss_mb,threads" > "$out/rss.csv"
receiver() {  # run N, seconds
  "$bin/headcast-receiver" --listen "127.0.0.1:$port" --plaintext --token "$token" --avatar demo="$out/demo.hcavatar" \
    --display none --duration "$2" --json "$out/receiver_$1.json" > /dev/null 2> "$out/receiver_$1.log" &
  rpid=$!
}
run=0
receiver $run "$restart"
sleep 2
for i in $(seq "$sessions"); do
  "$bin/headcast-sender" --target "127.0.0.1:$port" --plaintext --token "$token" --avatar-id demo --synthetic 300 --loop \
    --duration "$total" --json "$out/sender_$i.json" > /dev/null 2> "$out/sender_$i.log" &
  pids+=($!)
done
tick=0
while kill -0 "${pids[0]}" 2>/dev/null; do
  if kill -0 "$rpid" 2>/dev/null; then
    [ $((tick % 5)) -eq 0 ] &&
      echo "$(elapsed),$run,$(awk '/VmRSS/{print $2/1024}' /proc/$rpid/status 2>/dev/null),$(awk '/Threads/{print $2}' /proc/$rpid/status 2>/dev/null)" >> "$out/rss.csv"
  else
    wait "$rpid" || true
    sleep 1  # the restart window
    run=$((run + 1))
    left=$(python3 -c "print(max(5, int($total - $(elapsed) + 5)))")
    receiver $run $((left < restart ? left : restart))
  fi
  tick=$((tick + 1))
  sleep 1
done
wait "${pids[@]}" || true
pids=()
kill -INT "$rpid" 2>/dev/null || true
wait "$rpid" || true
python3 - "$out" "$command" "$sessions" "$minutes" "$restart" <<'PY'
import csv, glob, json, os, sys
out, command, sessions, minutes, restart = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
senders = [json.load(open(p)) for p in sorted(glob.glob(os.path.join(out, "sender_*.json")))]
receivers = [json.load(open(p)) for p in sorted(glob.glob(os.path.join(out, "receiver_*.json")))]
rows = list(csv.DictReader(open(os.path.join(out, "rss.csv"))))
# Restart windows from the receivers' logs: the last line of one run to "listening" in the next.
import datetime, re
def times(path):
    t = [datetime.datetime.strptime(m.group(1), "%H:%M:%S.%f")
         for m in (re.match(r"\[(\d\d:\d\d:\d\d\.\d+)\]", l) for l in open(path)) if m]
    listening = [datetime.datetime.strptime(m.group(1), "%H:%M:%S.%f")
                 for m in (re.match(r"\[(\d\d:\d\d:\d\d\.\d+)\].*listening", l) for l in open(path)) if m]
    return t, listening
logs = [times(os.path.join(out, f"receiver_{k}.log")) for k in range(len(glob.glob(os.path.join(out, "receiver_*.log"))))]
windows = [(logs[k + 1][1][0] - logs[k][0][-1]).total_seconds() for k in range(len(logs) - 1) if logs[k][0] and logs[k + 1][1]]
per_run = {}
for r in rows:
    if r["rss_mb"]:
        per_run.setdefault(r["run"], []).append(float(r["rss_mb"]))
sent = sum(s["frames_sent"] for s in senders)
submitted = sum(s["frames_submitted"] for s in senders)
dropped = sum(s["frames_dropped"] for s in senders)
received = sum(r["frames_received"] for r in receivers)
report = {
    "command": command, "sessions": sessions, "minutes": minutes, "restart_every_s": restart,
    "receiver_runs": len(receivers), "restarts": len(receivers) - 1,
    "frames_submitted": submitted, "frames_sent": sent, "frames_dropped_by_senders": dropped,
    "frames_received": received, "frames_sent_not_received": sent - received,
    "frames_bad": sum(r["frames_bad"] for r in receivers),
    "sender_connects": [s["connects"] for s in senders],
    "restart_windows_s": [round(w, 2) for w in windows],
    "dropped_s_per_restart_per_session": round(dropped / max(1, (len(receivers) - 1) * sessions) / 30, 2),
    "rss_mb_first_last_per_run": {k: [round(v[0], 1), round(v[-1], 1), round(max(v), 1)] for k, v in sorted(per_run.items(), key=lambda kv: int(kv[0]))},
}
json.dump(report, open(os.path.join(out, "soak.json"), "w"), indent=2)
print(json.dumps(report, indent=2))
PY
