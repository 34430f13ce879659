#!/usr/bin/env bash
# The one-command demo: sets headcast up (packages, build), then runs a real
# session on loopback. The synthetic demo subject, seen as a ZED2-style RGB-D
# camera sees it (colour + depth, rendered here from models/demo/subject.json:
# the frames after those its avatar was made from), goes through the real
# sender (file source, the RGB-D tracker, the codec, gRPC over 127.0.0.1) to
# the real receiver holding the demo avatar, which shows it in a
# window when there is a display and renders offscreen otherwise. It writes an
# MP4 (input | head-model fit | avatar, labelled, with the session's
# figures), a JSON report (frames, fps, glass-to-glass latency, uplink kbit/s,
# the avatar's PSNR against the input frames) and a PNG plot, and prints
# where they are.
#
#   deploy/demo.sh                                     # the bundled subject (RGB-D) and avatar
#   deploy/demo.sh --input models/demo/demo_sequence.mp4   # the same frames, colour only
#   deploy/demo.sh --input /dev/video0 --avatar me.hcavatar --head-model ict.npz   # your camera, your avatar
# Options: --input SRC (camera, video, image or RGB-D folder), --avatar A.hcavatar,
# --head-model builtin|M.npz, --intrinsics fx,fy,cx,cy | --fov DEG, --duration S,
# --display auto|window|offscreen, --out DIR, --no-setup.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
input=""  # default: the demo subject's RGB-D frames, rendered below
avatar=$root/models/demo_avatar.hcavatar
head_model=builtin intrinsics="" fov="" duration="" display=auto setup=1
out=${HEADCAST_DEMO_OUT:-$root/out/demo}
while [ $# -gt 0 ]; do
  case $1 in
    --input) input=$2; shift 2 ;;
    --avatar) avatar=$2; shift 2 ;;
    --head-model) head_model=$2; shift 2 ;;
    --intrinsics) intrinsics=$2; shift 2 ;;
    --fov) fov=$2; shift 2 ;;
    --duration) duration=$2; shift 2 ;;
    --display) display=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --no-setup) setup=0; shift ;;
    -h|--help) sed -n '2,19p' "$0"; exit 0 ;;
    *) echo "demo: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
[ "$setup" = 1 ] && "$root/deploy/setup.sh"
bin=$root/build/bin
python=${HEADCAST_PYTHON:-/usr/bin/python3}
[ -e "$avatar" ] || { echo "demo: no avatar at $avatar (deploy/make_default_models.sh makes the default)" >&2; exit 1; }
mkdir -p "$out"
rm -f "$out"/{shown.csv,arrival.csv,receiver.json,sender.json,wire.txt,received.hcrec,sent_frames.csv}

if [ -z "$input" ]; then
  # The bundled subject: its frames after the avatar's, rendered as colour + millimetre depth.
  input=$out/subject_rgbd
  rm -rf "$input"
  mapfile -t subject < <("$python" -c "
import json; s = json.load(open('$root/models/demo/subject.json'))
print(s['first_frame']); print(s['frames']); print(s['size']); [print(v) for v in s['shape']]")
  shape_flags=()
  for v in "${subject[@]:3}"; do shape_flags+=(--shape "$v"); done
  "$bin/headcast-headmodel" render-rgbd builtin --out "$input" --first-frame "${subject[0]}" --frames "${subject[1]}" \
    --size "${subject[2]}" "${shape_flags[@]}" > /dev/null
fi
# The bundled subject's camera is the one its avatar was prepared with.
if [ -z "$intrinsics$fov" ] && { [ "$input" = "$out/subject_rgbd" ] || [ "$input" = "$root/models/demo/demo_sequence.mp4" ]; }; then
  intrinsics=$("$python" -c "import json; print(','.join(str(v) for v in json.load(open('$root/models/demo/dataset.json'))['crop']['source_camera']))")
fi
camera=()
[ -n "$intrinsics" ] && camera=(--intrinsics "$intrinsics")
[ -n "$fov" ] && camera=(--fov "$fov")
if [ -z "$duration" ]; then
  case $input in
    /dev/*|v4l2:*) duration=30 ;;  # a camera: 30 s
    *) duration=0 ;;               # a recording: to its end
  esac
fi
if [ "$display" = auto ]; then
  if [ -n "${DISPLAY:-}" ]; then display=window; else display=offscreen; fi
fi

port=$((20000 + RANDOM % 20000))
"$bin/headcast-receiver" --listen "127.0.0.1:$port" --plaintext --allow-no-token --avatar "demo=$avatar" \
  --head-model "$head_model" --display "$display" --video "$out/avatar.mp4" --target-delay 0.05 \
  --display-csv "$out/shown.csv" --latency-csv "$out/arrival.csv" --json "$out/receiver.json" \
  --record "$out/received.hcrec" > /dev/null 2> "$out/receiver.log" &
rx=$!
trap 'kill "$rx" 2>/dev/null || true' EXIT
for _ in $(seq 200); do grep -q listening "$out/receiver.log" && break; sleep 0.05; done
grep -q listening "$out/receiver.log" || { cat "$out/receiver.log" >&2; exit 1; }

# Bytes on the wire: the sender's socket counters (payload + 52 B of IP/TCP headers per segment), every 0.5 s.
(
  while kill -0 "$rx" 2>/dev/null; do
    ss -tinH state established "( dport = :$port )" 2>/dev/null | awk -v t="$(date +%s.%N)" '
      { for (i = 1; i <= NF; i++) { split($i, kv, ":");
          if (kv[1] == "bytes_sent") bs = kv[2]; if (kv[1] == "segs_out") so = kv[2]; } }
      END { if (so > 0) printf "%s %d\n", t, bs + 52 * so }' >> "$out/wire.txt"
    sleep 0.5
  done
) &
sampler=$!
echo "demo: streaming $input -> receiver on 127.0.0.1:$port ($display)"
"$bin/headcast-sender" --target "127.0.0.1:$port" --plaintext --avatar-id demo --head-model "$head_model" \
  --input "$input" --identity-from "$avatar" "${camera[@]}" --duration "$duration" --json "$out/sender.json" \
  --frames-csv "$out/sent_frames.csv" \
  > /dev/null 2> "$out/sender.log" || { tail -5 "$out/sender.log" >&2; exit 1; }
sleep 1  # the jitter buffer and the last frames
kill -INT "$rx"
wait "$rx" || true
kill "$sampler" 2>/dev/null || true
trap - EXIT

h=$("$python" -c "import json; print(json.load(open('$out/receiver.json')).get('rendered', 0))")
[ "$h" -gt 0 ] || { echo "demo: the receiver showed nothing; see $out/receiver.log" >&2; exit 1; }

"$python" - "$out" "$input" <<'PY'
import csv, json, statistics, sys
out, source = sys.argv[1], sys.argv[2]
rx = json.load(open(f"{out}/receiver.json"))
tx = json.load(open(f"{out}/sender.json"))
shown = [r for r in csv.DictReader(open(f"{out}/shown.csv"))]
arrival = [float(r["latency_ms"]) for r in csv.DictReader(open(f"{out}/arrival.csv"))]
glass = sorted(float(r["glass_to_glass_ms"]) for r in shown)
def pct(v, p):
    return v[min(len(v) - 1, int(round(p / 100 * (len(v) - 1))))] if v else None
wire = [tuple(map(float, l.split())) for l in open(f"{out}/wire.txt") if l.strip()] if glass else []
t = tx.get("tracking", {})
report = {
    "input": source,
    "frames": {"read": t.get("frames_read"), "fitted": t.get("frames_fitted"), "sent": tx.get("frames_sent"),
               "received": rx.get("frames_received"), "shown": rx.get("rendered")},
    "fps_shown": (len(shown) - 1) / (float(shown[-1]["shown_s"]) - float(shown[0]["shown_s"])) if len(shown) > 1 else None,
    "glass_to_glass_ms": {"p50": pct(glass, 50), "p95": pct(glass, 95),
                          "what": "camera frame captured (the recording's frame due) to the avatar frame shown, "
                                  "same host clock"},
    "stages_ms_median": {"landmarks (detect/track + 68 points)": t.get("landmarks_ms_median"),
                         "fit": t.get("fit_ms_median"),
                         "capture to arrival (tracking, encode, gRPC, decode)": statistics.median(arrival) if arrival else None,
                         "jitter buffer (target delay)": 50.0,
                         "render": rx.get("render_ms_median"), "display": rx.get("show_ms_median")},
    "uplink_kbps": {"payload": tx.get("payload_kbps"),
                    "on_wire": (8e-3 * (wire[-1][1] - wire[0][1]) / (wire[-1][0] - wire[0][0])) if len(wire) >= 2 else None,
                    "what": "on_wire: the sender socket's bytes with 52 B of IP/TCP headers per segment"},
}
json.dump(report, open(f"{out}/report.json", "w"), indent=2)
with open(f"{out}/latency.csv", "w") as f:
    f.write("frame,glass_to_glass_ms\n")
    for i, r in enumerate(shown):
        f.write(f"{i},{r['glass_to_glass_ms']}\n")
PY
"$bin/headcast-train" plot --series "$out/latency.csv:glass_to_glass_ms:glass to glass" --title "headcast demo" \
  --x-label "shown frame" --y-label ms --out "$out/latency.png" > /dev/null
# What the receiver showed against what the camera saw: input | head-model fit | avatar, with the figures.
caption=$("$python" - "$out" <<'PY'
import json, sys
r = json.load(open(f"{sys.argv[1]}/report.json"))
f = lambda v, d=1: "?" if v is None else f"{v:.{d}f}"
k = r["uplink_kbps"]
print(f"headcast demo: {f(r['fps_shown'])} fps shown, glass to glass {f(r['glass_to_glass_ms']['p50'], 0)} ms (p50), "
      f"{f(k['on_wire'])} kbit/s on the wire ({f(k['payload'])} payload)")
PY
)
if [ -f "$input" ] || [ -d "$input" ]; then
  rm -rf "$out/compare"
  if "$bin/headcast-train" compare --head-model "$head_model" --avatar "$avatar" --recording "$out/received.hcrec" \
      --truth "$input" --frame-map "$out/sent_frames.csv" --out "$out/compare" --caption "$caption" \
      > "$out/compare.json" 2> "$out/compare.log"; then
    cp "$out/compare/side_by_side.mp4" "$out/side_by_side.mp4"
    "$python" - "$out" <<'PY'
import json, sys
out = sys.argv[1]
r = json.load(open(f"{out}/report.json"))
c = json.load(open(f"{out}/compare.json"))
r["avatar_vs_truth"] = {k: c[k] for k in ("frames", "psnr_db", "ssim", "psnr_db_worst_5_percent")}
r["avatar_vs_truth"]["what"] = c["how"]
json.dump(r, open(f"{out}/report.json", "w"), indent=2)
PY
  else
    echo "demo: the comparison with the input failed (see $out/compare.log); side_by_side.mp4 is the avatar alone" >&2
    cp "$out/avatar.mp4" "$out/side_by_side.mp4"
  fi
else
  cp "$out/avatar.mp4" "$out/side_by_side.mp4"  # a camera: only the avatar was recorded
fi

"$python" - "$out" <<'PY'
import json, sys
r = json.load(open(f"{sys.argv[1]}/report.json"))
g, k = r["glass_to_glass_ms"], r["uplink_kbps"]
f = lambda v, d=1: "?" if v is None else f"{v:.{d}f}"
print(f"\nheadcast demo: {r['frames']['shown']} frames shown at {f(r['fps_shown'])} fps; glass to glass "
      f"p50 {f(g['p50'])} ms, p95 {f(g['p95'])} ms; uplink {f(k['payload'], 2)} kbit/s payload, "
      f"{f(k['on_wire'], 2)} kbit/s on the wire")
v = r.get("avatar_vs_truth")
if v:
    print(f"the avatar against the true frames: {f(v['psnr_db'])} dB PSNR, SSIM {f(v['ssim'], 3)} "
          f"over {v['frames']} frames (worst 5 %: {f(v['psnr_db_worst_5_percent'])} dB)")
PY
echo "  $out/side_by_side.mp4   input | head-model fit | avatar"
echo "  $out/report.json        what was measured"
echo "  $out/latency.png        glass-to-glass latency per shown frame"
echo
echo "next:"
echo "  your own avatar:    build/bin/headcast-train create --input me.mp4 --out me.hcavatar   (docs/own_avatar.md)"
echo "  with a camera:      deploy/demo.sh --no-setup --input /dev/video0 --avatar me.hcavatar --head-model models/ict_facekit.npz"
echo "  in a call:          the receiver's --display v4l2:/dev/videoN, a virtual camera (docs/calls.md)"
