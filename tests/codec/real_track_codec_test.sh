#!/usr/bin/env bash
# The parameter codec on a real person's track: talking_d14 (../shared/data;
# skipped without it) tracked with ICT-FaceKit, coded and decoded by
# headcast-bench codec. Every value must come back within half its quantisation
# step, in the bits a narrow link can carry; a recording of another head model
# is refused by name.
set -u
bin=$1; data=$2
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT
"$bin/headcast-headmodel" convert ict --folder "$data/head-models/ict-facekit" --out "$tmp/ict.npz" > /dev/null 2>&1 ||
  { echo "SKIP: no ../shared/data (set HEADCAST_DATA)"; exit 77; }
"$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 150 \
  --out "$tmp/d14.hcrec" --json "$tmp/track.json" > /dev/null 2>&1 || bad "tracking failed"
json() { grep -o "\"$1\": [0-9.e+-]*" "$tmp/codec.json" | head -1 | awk '{print $2}'; }
"$bin/headcast-bench" codec --recording "$tmp/d14.hcrec" --head-model "$tmp/ict.npz" --key-interval 300 \
  --json "$tmp/codec.json" > /dev/null 2>&1 || bad "codec bench failed"
frames=$(json frames) beyond=$(json values_beyond_half_a_step) bits=$(json bits_per_frame_mean)
[ "$frames" = 150 ] && ok "150 real frames coded" || bad "frames: $frames"
[ "$beyond" = 0 ] && ok "every value of every frame within half a step" || bad "$beyond values beyond half a step"
awk "BEGIN{exit !($bits > 40 && $bits < 200)}" && ok "$bits bits per frame (53 expressions, 18 pose values)" ||
  bad "bits per frame: $bits"
out=$("$bin/headcast-bench" codec --recording "$tmp/d14.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "recorded with head model" <<<"$out" && ok "another head model's recording refused" ||
  bad "foreign model: rc=$rc $out"
checks_summary "real-track codec"
