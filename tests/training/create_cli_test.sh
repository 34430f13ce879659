#!/usr/bin/env bash
# headcast-train create as a user runs it, on tiny settings: a rendered talking
# head (image folder) -> stop after prep -> a second call refused without
# --resume -> --resume finishes (fine-tune with two ranks, eval) -> the summary
# (held-out figures, an H.264 side-by-side, the commands to use the avatar);
# resuming with other options is refused; a video recorded as from a camera
# goes through the quality check; a head model without a general model is refused;
# compare renders the session's received frames beside their input frames.
set -u
bin=$1 src=$2 python=${3:-/usr/bin/python3}
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'kill "${rx:-}" 2>/dev/null; rm -rf "$tmp"' EXIT
json() { "$python" -c "import json,sys; j=json.load(open('$1')); print($2)" 2>/dev/null; }

"$bin/headcast-headmodel" render-rgbd builtin --out "$tmp/seq" --frames 48 --size 320 --shape 0=0.8 > /dev/null 2>&1
tiny=(--head-model builtin --resolution 128 --iterations 6 --test-frames 8 --no-landmarks)

"$bin/headcast-train" create --input "$tmp/seq/rgb" --out "$tmp/me.hcavatar" "${tiny[@]}" --stop-after prep \
  > "$tmp/a.json" 2> "$tmp/a.err"
[ $? -eq 0 ] && [ "$(json "$tmp/me.create/create.json" "sorted(j['stages'])")" = "['prep']" ] &&
  [ ! -e "$tmp/me.hcavatar" ] && [ "$(json "$tmp/a.json" "j['frames']['fitted'] >= 40")" = True ] &&
  grep -q "stopped after prep" "$tmp/a.err" && grep -q "about .* in all" "$tmp/a.err" &&
  ok "create --stop-after prep: the dataset, no avatar yet, the plan's time said" ||
  bad "stop after prep: $(tail -3 "$tmp/a.err")"

out=$("$bin/headcast-train" create --input "$tmp/seq/rgb" --out "$tmp/me.hcavatar" "${tiny[@]}" 2>&1)
[ $? -ne 0 ] && grep -q "holds an earlier create: --resume" <<<"$out" && ok "a second create without --resume refused" ||
  bad "no --resume: $out"

"$bin/headcast-train" create --input "$tmp/seq/rgb" --out "$tmp/me.hcavatar" "${tiny[@]}" --processes 2 --resume \
  > "$tmp/b.json" 2> "$tmp/b.err"
status=$?
codec=$(ffprobe -v error -select_streams v:0 -show_entries stream=codec_name -of csv=p=0 \
  "$tmp/me.create/eval/side_by_side.mp4" 2>/dev/null)
[ $status -eq 0 ] && [ -s "$tmp/me.hcavatar" ] && [ "$codec" = h264 ] &&
  [ "$(json "$tmp/b.json" "10 < j['held_out']['psnr_db'] < 60 and j['held_out']['frames'] == 8")" = True ] &&
  [ "$(json "$tmp/b.json" "'--avatar me=$tmp/me.hcavatar' in j['use']['receiver'] and '--identity-from $tmp/me.hcavatar' in j['use']['sender']")" = True ] &&
  [ "$(json "$tmp/me.create/fine_tune.json" "j['fit']['processes']")" = 2 ] &&
  grep -q "prep: done in an earlier run" "$tmp/b.err" && grep -q "held-out frames: PSNR" "$tmp/b.err" &&
  ! pgrep -f "$tmp/me.hcavatar" > /dev/null &&
  ok "create --resume: fine-tune on two ranks, eval; PSNR, an H.264 side-by-side and the commands reported" ||
  bad "resume: status $status codec '$codec' $(tail -5 "$tmp/b.err")"

# The printed commands work as printed: the receiver holds the new avatar; the
# sender (a video for /dev/video0) drives it.
port=$((20000 + $$ % 20000))
receiver=$(json "$tmp/b.json" "j['use']['receiver']")
sender=$(json "$tmp/b.json" "j['use']['sender'].replace('/dev/video0', '$tmp/seq/rgb')")
eval "exec $receiver --listen 127.0.0.1:$port --display none --json $tmp/rx.json --record $tmp/rx.hcrec" \
  > /dev/null 2> "$tmp/rx.log" &
rx=$!
wait_for "$tmp/rx.log" listening || bad "the printed receiver never listened"
eval "$sender --target 127.0.0.1:$port --frames-csv $tmp/sent.csv --json $tmp/tx.json" > /dev/null 2> "$tmp/tx.log"
sleep 0.5
kill -TERM "$rx"; wait "$rx"; rx=
[ "$(json "$tmp/rx.json" "j['frames_received'] >= 30 and j['rendered'] > 0")" = True ] &&
  ok "the printed receiver and sender commands run a session with the new avatar" ||
  bad "printed commands: $(cat "$tmp/rx.json" 2>&1 | head -c 600) $(tail -2 "$tmp/rx.log")"
# Prep anchored the training frames (its default); the avatar carries the
# references and the sender holds the frames it tracks to them, its landmarks
# as found (unfiltered), as prep took them.
[ "$(json "$tmp/me.create/dataset/dataset.json" "len(j['tracking_anchor']['grey'])")" = 400 ] &&
  [ "$(json "$tmp/tx.json" "j['tracking']['photometric_anchor'] and j['tracking']['frames_anchored'] > 0.8 * j['tracking']['frames_fitted'] and j['tracking']['landmark_filter'] == 'off'")" = True ] &&
  ok "the photometric anchor from prep to avatar to sender: $(json "$tmp/tx.json" "j['tracking']['frames_anchored']") of $(json "$tmp/tx.json" "j['tracking']['frames_fitted']") sent frames anchored" ||
  bad "anchor to the sender: $(json "$tmp/tx.json" "j['tracking']") $(grep -i anchor "$tmp/tx.log" | head -3)"
# The expression fit travels the same way: prep records it, the avatar carries
# it, the sender fits with it.
[ "$(json "$tmp/me.create/dataset/dataset.json" "j['tracking_fit']")" = "$(json "$tmp/tx.json" "j['tracking']['expression_fit']")" ] &&
  [ "$(json "$tmp/tx.json" "j['tracking']['expression_fit']['expression_prior']")" != "0.002" ] &&
  ok "the expression fit from prep to avatar to sender: $(json "$tmp/tx.json" "j['tracking']['expression_fit']")" ||
  bad "expression fit to the sender: $(json "$tmp/me.create/dataset/dataset.json" "j.get('tracking_fit')") against $(json "$tmp/tx.json" "j['tracking'].get('expression_fit')")"

# What the receiver showed against the frames the sender tracked (the demo's comparison).
received=$(json "$tmp/rx.json" "j['frames_received']")
"$bin/headcast-train" compare --avatar "$tmp/me.hcavatar" --recording "$tmp/rx.hcrec" --truth "$tmp/seq/rgb" \
  --frame-map "$tmp/sent.csv" --out "$tmp/cmp" --caption "a caption" > "$tmp/cmp.json" 2> "$tmp/cmp.err"
status=$?
width=$(ffprobe -v error -select_streams v:0 -show_entries stream=codec_name,width -of csv=p=0 \
  "$tmp/cmp/side_by_side.mp4" 2>/dev/null)
[ $status -eq 0 ] && [ "$width" = "h264,384" ] &&
  [ "$(json "$tmp/cmp.json" "j['frames'] == $received and 5 < j['psnr_db'] < 60 and 0 < j['ssim'] <= 1")" = True ] &&
  [ "$(($(wc -l < "$tmp/cmp/per_frame.csv") - 1))" = "$received" ] &&
  ok "compare: $received received frames against their input frames, three H.264 panels" ||
  bad "compare: status $status video '$width' $(head -c 300 "$tmp/cmp.json") $(tail -2 "$tmp/cmp.err")"
printf 'frame,psnr\n0,1\n' > "$tmp/foreign.csv"
out=$("$bin/headcast-train" compare --avatar "$tmp/me.hcavatar" --recording "$tmp/rx.hcrec" --truth "$tmp/seq/rgb" \
  --frame-map "$tmp/foreign.csv" --out "$tmp/cmp2" 2>&1)
[ $? -ne 0 ] && grep -q "not a sender --frames-csv" <<<"$out" && ok "compare refuses a CSV that is no frame map" ||
  bad "foreign map: $out"
head -3 "$tmp/sent.csv" > "$tmp/short.csv"
out=$("$bin/headcast-train" compare --avatar "$tmp/me.hcavatar" --recording "$tmp/rx.hcrec" --truth "$tmp/seq/rgb" \
  --frame-map "$tmp/short.csv" --out "$tmp/cmp3" 2>&1)
[ $? -ne 0 ] && grep -q "no input frame for sequence" <<<"$out" && ok "compare refuses a frame map without the received frames" ||
  bad "short map: $out"
mkdir -p "$tmp/few" && cp "$tmp/seq/rgb/00000.png" "$tmp/seq/rgb/00001.png" "$tmp/few/"
out=$("$bin/headcast-train" compare --avatar "$tmp/me.hcavatar" --recording "$tmp/rx.hcrec" --truth "$tmp/few" \
  --out "$tmp/cmp4" 2>&1)
[ $? -ne 0 ] && grep -q "ends before input frame" <<<"$out" && ok "compare refuses an input shorter than the recording" ||
  bad "short input: $out"

out=$("$bin/headcast-train" create --input "$tmp/seq/rgb" --out "$tmp/me.hcavatar" --head-model builtin \
  --resolution 128 --iterations 7 --test-frames 8 --resume 2>&1)
[ $? -ne 0 ] && grep -q "iterations = 6, not 7" <<<"$out" && ok "resuming with other options refused, naming them" ||
  bad "other options: $out"

# A video played as a camera: recorded with guidance, then judged. The rendered
# head hardly turns in 2 s, so the check fails and says so; --accept-recording goes on.
ffmpeg -loglevel error -y -framerate 30 -i "$tmp/seq/rgb/%05d.png" -c:v libx264 -pix_fmt yuv420p "$tmp/cam.mp4"
out=$("$bin/headcast-train" create --input "$tmp/cam.mp4" --record 1 --out "$tmp/cam.hcavatar" "${tiny[@]}" 2>&1)
[ $? -ne 0 ] && grep -q "poor avatar (.*turn further" <<<"$out" && grep -q "record again" <<<"$out" &&
  ok "a recording whose head does not turn is refused before training, saying what to do" ||
  bad "quality check: $out"
rm -rf "$tmp/cam.create"
"$bin/headcast-train" create --input "$tmp/cam.mp4" --record 1 --accept-recording --out "$tmp/cam.hcavatar" \
  "${tiny[@]}" --stop-after prep > "$tmp/c.json" 2> "$tmp/c.err"
frames=$(ls "$tmp/cam.create/recording" 2>/dev/null | wc -l)
[ $? -eq 0 ] && [ "$frames" -ge 10 ] && [ "$(json "$tmp/c.json" "j['recording']['checked_frames'] > 0 and j['frames']['fitted'] >= 8")" = True ] &&
  ok "--accept-recording: $frames frames recorded and prepared" || bad "accept recording: $frames $(tail -3 "$tmp/c.err")"

"$bin/headcast-headmodel" convert builtin --out "$tmp/other.npz" > /dev/null 2>&1
out=$("$bin/headcast-train" create --input "$tmp/seq/rgb" --out "$tmp/x.hcavatar" --head-model "$tmp/other.npz" 2>&1)
[ $? -ne 0 ] && grep -q "needs --general" <<<"$out" && ok "a head model without --general refused" || bad "general: $out"
out=$("$bin/headcast-train" create --input "$tmp/nothing" --out "$tmp/y.hcavatar" "${tiny[@]}" 2>&1)
[ $? -ne 0 ] && grep -q "nothing" <<<"$out" && ok "a missing input refused, named" || bad "missing input: $out"

checks_summary create_cli_test
