#!/usr/bin/env bash
# A live RGB-D session on loopback (issue #25): a rendered RGB-D sequence of
# the built-in head with known parameters (headcast-headmodel render-rgbd,
# depth noise in mm) through headcast-sender --input (the RGB-D fit, identity
# from the first frames then frozen; the sender pinned to one core, frames read
# as fast as it tracks them) to headcast-receiver; ms per stage from the
# sender's report, head position and rotation error against the truth.
# With --stereo B the sender reads side-by-side stereo frames of the same
# sequence (a right camera B metres to the right, rendered by render-rgbd
# --stereo-baseline, as an H.264 video) through zed: and the stereo
# calibration: depth by stereo matching in the face's box, as a ZED-style
# camera gives it. With --realtime the frames come at 30 fps, as from a camera
# (the sender tracks the newest; the identity is fitted beside tracking, on
# the other core), instead of as fast as the sender takes them.
#   bench/live_rgbd.sh OUT [--frames N] [--noise MM] [--stereo BASELINE_M] [--realtime]
# Writes OUT/live_rgbd.json and prints it.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${HEADCAST_PYTHON:-/usr/bin/python3}
bin=${HEADCAST_BIN:-$root/build/bin}
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
command="bench/live_rgbd.sh OUT $*"
frames=60 noise=1 stereo=0 pacing=none pin=(taskset -c 0)
while [ $# -gt 0 ]; do
  case $1 in
    --realtime) pacing=realtime pin=(); shift ;;
    --frames) frames=$2; shift 2 ;;
    --noise) noise=$2; shift 2 ;;
    --stereo) stereo=$2; shift 2 ;;
    *) echo "live_rgbd: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$out"
out=$(cd "$out" && pwd)
"$bin/headcast-headmodel" render-rgbd builtin --out "$out/seq" --frames "$frames" --shape 0=0.8 \
  --depth-noise "$noise" --stereo-baseline "$stereo" > "$out/render.log" 2>&1
input=(--input "$out/seq")
if [ "$stereo" != 0 ]; then
  # A video, as a camera stream: decoding a PNG per frame would measure the disk format, not the camera.
  ffmpeg -loglevel error -y -framerate 30 -i "$out/seq/side_by_side/%05d.png" -c:v libx264 -qp 0 -pix_fmt yuv444p \
    "$out/seq/side_by_side.mp4"
  input=(--input "zed:$out/seq/side_by_side.mp4" --stereo-calibration "$out/seq/stereo.yml")
fi
fx=$("$python" -c "import json; print(json.load(open('$out/seq/truth.json'))['camera']['fx'])")
"$bin/headcast-avatar" create --resolution 128 --out "$out/a.hcavatar" > /dev/null 2>&1
port=$((20000 + $$ % 20000))
# The receiver of a real call runs elsewhere: here it yields the cores to the sender measured.
nice -n 19 "$bin/headcast-receiver" --listen "127.0.0.1:$port" --plaintext --allow-no-token --avatar "demo=$out/a.hcavatar" \
  --display none --json "$out/receiver.json" > /dev/null 2> "$out/receiver.log" &
rx=$!
trap 'kill "$rx" 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q listening "$out/receiver.log" && break; sleep 0.1; done
"${pin[@]}" "$bin/headcast-sender" --target "127.0.0.1:$port" --plaintext --avatar-id demo "${input[@]}" \
  --intrinsics "$fx,$fx,319.5,239.5" ${HEADCAST_SENDER_FLAGS:-} --pacing "$pacing" --record "$out/live.hcrec" --frames-csv "$out/frames.csv" \
  --json "$out/sender.json" > /dev/null 2> "$out/sender.log"
sleep 0.5
kill -INT "$rx"; wait "$rx" || true
compare() { "$python" "$root/tests/tracking/compare_track_truth.py" --proto-dir "$root/proto" --recording "$out/live.hcrec" \
  --truth "$out/seq/truth.json" --frame-map "$out/frames.csv" --max-translation-mm 1000 "$@"; }
compare > "$out/truth.json"
# The frames tracked once the identity was made (live, those before it were tracked with the identity so far).
made=$("$python" -c "import json; k=json.load(open('$out/sender.json'))['tracking']; print(k['identity_frames'] + k['provisional_identity_frames'])")
compare --from-sequence "$made" > "$out/truth_after_identity.json"
"$python" - "$out" "$command" "$noise" "$stereo" "$pacing" <<'PY'
import json, os, sys
out, command, noise, stereo, pacing = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
s = json.load(open(os.path.join(out, "sender.json")))
r = json.load(open(os.path.join(out, "receiver.json")))
t = json.load(open(os.path.join(out, "truth.json")))
ta = json.load(open(os.path.join(out, "truth_after_identity.json")))
k = s["tracking"]
stage = {x: k[x] for x in ("read_wait_ms_median", "landmarks_ms_median", "landmarks_ms_p95", "depth_ms_median",
                           "fit_ms_median", "fit_ms_p95", "capture_to_params_ms_median", "capture_to_params_ms_p95",
                           "tracking_capture_to_params_ms_median", "tracking_capture_to_params_ms_p95",
                           "provisional_capture_to_params_ms_median", "provisional_capture_to_params_ms_p95") if x in k}
per_frame = k["landmarks_ms_median"] + k["fit_ms_median"]
depth = f"stereo, baseline {stereo} m, matched in the face's box" if stereo > 0 else f"rendered, {noise} mm noise"
result = {"command": command, "depth": depth, "depth_noise_mm": noise if stereo == 0 else None,
          "frames_read": k["frames_read"],
          "frames_with_depth": k["frames_with_depth"], "frames_fitted": k["frames_fitted"],
          "pacing": "realtime (30 fps, as a camera)" if pacing == "realtime" else "none (as fast as the sender takes them, one core)",
          "identity_frames": k["identity_frames"],
          "provisional_identity_frames": k.get("provisional_identity_frames"),
          "identity_made_after_s": k.get("identity_made_after_s"),
          "frames_skipped_behind_tracker": k["frames_skipped_behind_tracker"],
          "frames_sent": s["frames_sent"], "frames_received": r["frames_received"], "stages_ms": stage,
          "track_ms_median_one_core": per_frame,
          "truth": {x: v for x, v in t.items() if "error" in x and "shape" not in x},
          "truth_after_identity": {x: v for x, v in ta.items() if ("error" in x and "shape" not in x) or x == "frames"}}
json.dump(result, open(os.path.join(out, "live_rgbd.json"), "w"), indent=2)
print(json.dumps(result, indent=2))
PY
