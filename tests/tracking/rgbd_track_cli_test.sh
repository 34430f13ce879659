#!/usr/bin/env bash
# RGB-D tracking end to end: a rendered RGB-D sequence with known parameters
# (headcast-headmodel render-rgbd) through headcast-track (dlib landmarks,
# RGB-D fit, identity calibration), compared with the truth; then prepared as
# a training dataset by headcast-train prep.
set -u
bin=$1 src=$2 python=${3:-/usr/bin/python3}
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'kill "${rx:-}" 2>/dev/null; rm -rf "$tmp"' EXIT

"$bin/headcast-headmodel" render-rgbd builtin --out "$tmp/seq" --frames 12 --shape 0=0.8 --depth-noise 0.5 \
  --stereo-baseline 0.12 > /dev/null && [ -s "$tmp/seq/associations.txt" ] && [ -s "$tmp/seq/stereo.yml" ] &&
  [ "$(ls "$tmp/seq/side_by_side" | wc -l)" = 12 ] && ok "render-rgbd writes a sequence (and side-by-side stereo)" ||
  bad "render-rgbd"
fx=$("$python" -c "import json; print(json.load(open('$tmp/seq/truth.json'))['camera']['fx'])")
"$bin/headcast-track" --input "$tmp/seq" --intrinsics "$fx,$fx,319.5,239.5" --calibration-frames 4 \
  --out "$tmp/t.hcrec" --json "$tmp/r.json" > /dev/null 2> "$tmp/log" && grep -q '"fitted_frames": 12' "$tmp/r.json" &&
  ok "12 of 12 RGB-D frames fitted" || bad "track: $(cat "$tmp/r.json" "$tmp/log" 2>/dev/null | tail -5)"
acc=$("$python" -c "import json; print(json.load(open('$tmp/r.json'))['rgbd_accuracy_mm_median'])" 2>/dev/null)
awk "BEGIN{exit !($acc < 1.5)}" 2>/dev/null && ok "RGB-D accuracy $acc mm" || bad "accuracy: $acc"
"$python" "$src/tests/tracking/compare_track_truth.py" --proto-dir "$src/proto" --recording "$tmp/t.hcrec" \
  --truth "$tmp/seq/truth.json" --max-translation-mm 10 > "$tmp/cmp.json" &&
  "$python" -c "import json,sys; j=json.load(open('$tmp/cmp.json')); sys.exit(0 if j['depth_error_mm_median'] < 2 else 1)" &&
  ok "head position within 10 mm, depth within 2 mm of the truth" || bad "truth: $(cat "$tmp/cmp.json")"
# Live: the sender tracks the RGB-D folder with the same tracker (identity from
# the first frames, then frozen) and streams to a receiver on loopback.
"$bin/headcast-avatar" create --resolution 128 --out "$tmp/a.hcavatar" > /dev/null 2>&1
port=$((20000 + $$ % 20000))
# live_session NAME MAX_DEPTH_ERROR_MM SENDER_INPUT_FLAGS...: a receiver on
# loopback, the sender on the input, then the tracking and the truth checked.
live_session() {
  local name=$1 max_depth_mm=$2
  shift 2
  "$bin/headcast-receiver" --listen "127.0.0.1:$port" --plaintext --allow-no-token --avatar "demo=$tmp/a.hcavatar" \
    --display none --json "$tmp/$name.rx.json" > /dev/null 2> "$tmp/$name.rx.log" &
  rx=$!
  wait_for "$tmp/$name.rx.log" listening || bad "receiver never listened"
  "$bin/headcast-sender" --target "127.0.0.1:$port" --plaintext --avatar-id demo "$@" --calibration-frames 4 \
    --pacing none --record "$tmp/$name.hcrec" --json "$tmp/$name.tx.json" > /dev/null 2> "$tmp/$name.tx.log"
  sleep 0.5
  kill -INT "$rx"; wait "$rx"; rx=
  "$python" -c "
import json, sys
t = json.load(open('$tmp/$name.tx.json')); r = json.load(open('$tmp/$name.rx.json'))
k = t['tracking']
sys.exit(0 if k['frames_with_depth'] == 12 and k['frames_fitted'] == 12 and t['frames_sent'] == 12
         and r['frames_received'] == 12 and k['capture_to_params_ms_median'] > 0 and k['identity_frames'] == 4
         and k['tracking_capture_to_params_ms_median'] > 0 and k['provisional_identity_frames'] == 0
         and k['identity_made_after_s'] is not None else 1)" &&
    ok "live $name session: 12 frames fitted with depth (4 fit the identity), sent and received" ||
    bad "live $name: $(head -30 "$tmp/$name.tx.json" 2>/dev/null) $(tail -3 "$tmp/$name.tx.log")"
  "$python" "$src/tests/tracking/compare_track_truth.py" --proto-dir "$src/proto" --recording "$tmp/$name.hcrec" \
    --truth "$tmp/seq/truth.json" --max-translation-mm 10 > "$tmp/$name.cmp.json" &&
    "$python" -c "import json,sys; j=json.load(open('$tmp/$name.cmp.json')); sys.exit(0 if j['depth_error_mm_median'] < $max_depth_mm else 1)" &&
    ok "live $name: head position within 10 mm, depth within $max_depth_mm mm of the truth" ||
    bad "live $name truth: $(cat "$tmp/$name.cmp.json")"
}
live_session rgbd 2 --input "$tmp/seq" --intrinsics "$fx,$fx,319.5,239.5"
# From side-by-side stereo (zed:): depth matched in the face's box only, on demand.
live_session stereo 5 --input "zed:$tmp/seq/side_by_side" --stereo-calibration "$tmp/seq/stereo.yml"
"$python" -c "import json,sys; sys.exit(0 if json.load(open('$tmp/stereo.tx.json'))['tracking']['depth_ms_median'] > 0 else 1)" &&
  ok "stereo depth made on demand (depth_ms reported)" || bad "stereo depth_ms: $(head -30 "$tmp/stereo.tx.json")"
# Prep takes every input the tracker takes: the RGB-D folder, tracked in-process.
"$bin/headcast-train" prep --input "$tmp/seq" --intrinsics "$fx,$fx,319.5,239.5" --no-calibrate --resolutions 128 \
  --test-frames 2 --out "$tmp/ds" > /dev/null 2> "$tmp/prep.log" &&
  "$python" -c "import json,sys; j=json.load(open('$tmp/ds/dataset.json')); sys.exit(0 if j['frames_fitted'] == 12 and j['identity'].startswith('RGB-D') else 1)" &&
  [ "$(ls "$tmp/ds/128/images" | wc -l)" = 12 ] && ok "prep on an RGB-D folder: 12 crops, identity from the depth" ||
  bad "prep on RGB-D: $(tail -3 "$tmp/prep.log") $(cat "$tmp/ds/dataset.json" 2>/dev/null | head -5)"
# Unreadable depth is a per-frame status.
printf 'junk' > "$tmp/seq/depth/00003.png"
"$bin/headcast-track" --input "$tmp/seq" --intrinsics "$fx,$fx,319.5,239.5" --calibration-frames 4 --max-frames 6 \
  --out "$tmp/u.hcrec" --json "$tmp/u.json" > /dev/null 2>&1 && grep -q '"unreadable_frames": 1' "$tmp/u.json" &&
  ok "unreadable depth is a status, the run completes" || bad "bad depth: $(cat "$tmp/u.json" 2>/dev/null)"
checks_summary "rgbd track cli"
