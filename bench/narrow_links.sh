#!/usr/bin/env bash
# Narrow links, synthetic and real tracks side by side (issue #25; root: netlab's
# namespaces and tbf): for each rate, the built-in head's synthetic talking
# sequence and a real recording (e.g. the four shared clips tracked with
# ICT-FaceKit and joined by `headcast-rec concat`), each streamed three ways:
# stream (batches paced to the link, on the gRPC stream: --datagrams off),
# datagrams (the same batches as encrypted UDP datagrams: the narrow-link
# default) and freshest (one newest frame per datagram, the receiver interpolates).
#   bench/narrow_links.sh OUT --recording REC --head-model M.npz [--rates "8 4 16"] [--duration S]
# Writes OUT/<track>_<rate>kbit_<mode>/ (netlab's outputs) and OUT/narrow_links.{json,md}.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${HEADCAST_PYTHON:-/usr/bin/python3}
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
command="bench/narrow_links.sh OUT $*"
recording="" head_model="" rates="8 4 16" duration=60
while [ $# -gt 0 ]; do
  case $1 in
    --recording) recording=$2; shift 2 ;;
    --head-model) head_model=$2; shift 2 ;;
    --rates) rates=$2; shift 2 ;;
    --duration) duration=$2; shift 2 ;;
    *) echo "narrow_links: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -f "$recording" ] && [ -f "$head_model" ] || { echo "narrow_links: give --recording and --head-model" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
for rate in $rates; do
  for mode in stream datagrams freshest; do
    case $mode in
      stream) flags=(--datagrams off) ;;
      datagrams) flags=(--datagrams on) ;;
      freshest) flags=(--datagrams on --freshest) ;;
    esac
    suffix=_$mode
    echo "== $(date +%H:%M:%S) synthetic, $rate kbit/s, $mode" >&2
    "$root/deploy/netlab/netlab.sh" --mode netns --rate "$rate" --duration "$duration" "${flags[@]}" \
      --out "$out/synthetic_${rate}kbit$suffix" > "$out/synthetic_${rate}kbit$suffix.log" 2>&1
    echo "== $(date +%H:%M:%S) real, $rate kbit/s, $mode" >&2
    "$root/deploy/netlab/netlab.sh" --mode netns --rate "$rate" --duration "$duration" "${flags[@]}" \
      --recording "$recording" --head-model "$head_model" --out "$out/real_${rate}kbit$suffix" \
      > "$out/real_${rate}kbit$suffix.log" 2>&1
  done
done
"$python" - "$out" "$command" "$rates" <<'PY'
import json, os, sys
out, command, rates = sys.argv[1], sys.argv[2], sys.argv[3].split()
rows = []
for rate in rates:
    for mode in ("stream", "datagrams", "freshest"):
        for track in ("synthetic", "real"):
            name = f"{track}_{rate}kbit_{mode}"
            n = json.load(open(os.path.join(out, name, "netlab.json")))
            sender = json.load(open(os.path.join(out, name, "sender.json")))
            rows.append({"track": track, "rate_kbit": float(rate), "mode": mode,
                         "uplink_kbps_on_wire": n["uplink_kbps_on_wire"], "payload_kbps": n["payload_kbps"],
                         "payload_bits_per_frame": 8 * sender["payload_bytes"] / max(1, sender["frames_sent"]),
                         "frames_per_s_delivered": n["frames_received"] / n["duration_s"],
                         "frames_per_s_streaming": n.get("fps_delivered_streaming"),
                         "datagrams_lost": n.get("datagrams_lost", 0), "key_frame_requests": n.get("key_frame_requests", 0),
                         "frames_per_message": n["frames_per_message"], "dropped_at_sender": n["frames_dropped_at_sender"],
                         "latency_ms_p50": n["latency_ms_p50"], "latency_ms_p95": n["latency_ms_p95"],
                         "latency_ms_median_last_fifth": n["latency_ms_median_last_fifth"]})
json.dump({"command": command, "rows": rows}, open(os.path.join(out, "narrow_links.json"), "w"), indent=2)
L = [f"Made by `{command}` (netns, TLS, tbf on the sender's egress; the sender's budget 92 % of the rate). "
     "synthetic: the built-in head's talking sequence (13 expressions); real: the recording given. "
     "stream: frames batched to the budget on the gRPC stream (`--datagrams off`); datagrams: the same batches as "
     "encrypted UDP datagrams (the narrow-link default); freshest: one newest frame per datagram (`--freshest`). "
     "payload bits/frame: the packets and their length prefixes. fps delivered: frames decoded at the receiver per "
     "second of the run, and once streaming (from the first frame's arrival to the last: the call's start-up, ~2 s of "
     "handshakes at 8 kbit/s, excluded); the receiver interpolates to its display rate.", "",
     "| track | link | mode | uplink on the wire (kbit/s) | payload (kbit/s) | payload bits/frame | fps delivered (run / streaming) | frames/message | capture→arrival p50 / p95 (ms) | dropped at sender | datagrams lost |",
     "|---|---|---|---|---|---|---|---|---|---|---|"]
for r in rows:
    L.append(f"| {r['track']} | {r['rate_kbit']:.0f} kbit/s | {r['mode']} | {r['uplink_kbps_on_wire']:.2f} | {r['payload_kbps']:.2f} | "
             f"{r['payload_bits_per_frame']:.0f} | {r['frames_per_s_delivered']:.1f} / {r['frames_per_s_streaming'] or 0:.1f} | "
             f"{r['frames_per_message']:.1f} | {r['latency_ms_p50']:.0f} / {r['latency_ms_p95']:.0f} | {r['dropped_at_sender']} | "
             f"{r['datagrams_lost']} |")
open(os.path.join(out, "narrow_links.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
PY
