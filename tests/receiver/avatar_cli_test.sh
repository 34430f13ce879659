#!/usr/bin/env bash
# headcast-avatar end to end on its own files; bad inputs refused with clear messages.
set -u
bin=$1
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT

"$bin" create --resolution 128 --out "$tmp/a.hcavatar" >/dev/null && ok "create" || bad "create"
"$bin" info "$tmp/a.hcavatar" | grep -q '"format": "headcast-avatar"' && ok "info" || bad "info"
"$bin" synth-params --frames 20 --out "$tmp/p.hcrec" >/dev/null && ok "synth-params" || bad "synth-params"
"$bin" synth-params --frames 20 --seed 7 --out "$tmp/q.hcrec" >/dev/null
out=$("$bin" render "$tmp/a.hcavatar" --params "$tmp/p.hcrec" --display offscreen --video "$tmp/v.mp4" --pacing none \
      --orbit 30 --transfer "$tmp/q.hcrec" --json "$tmp/s.json" 2>&1)
grep -q '"rendered": 20' "$tmp/s.json" && [ -s "$tmp/v.mp4" ] && ok "render offscreen + video, orbit, transfer" || bad "render: $out"
out=$("$bin" render "$tmp/a.hcavatar" --head-model "$tmp/none.npz" --display none 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "none.npz" <<<"$out" && ok "missing head model refused" || bad "missing head model: $out"
head -c 3000 "$tmp/a.hcavatar" > "$tmp/cut.hcavatar"
out=$("$bin" render "$tmp/cut.hcavatar" --display none 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "cut.hcavatar" <<<"$out" && ok "truncated avatar refused" || bad "truncated: $out"
echo "garbage" > "$tmp/g.hcrec"
out=$("$bin" render "$tmp/a.hcavatar" --params "$tmp/g.hcrec" --display none 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "not a headcast parameter recording" <<<"$out" && ok "foreign recording refused" || bad "foreign rec: $out"
out=$("$bin" render "$tmp/a.hcavatar" --display hologram 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "unknown display" <<<"$out" && ok "unknown display refused" || bad "display: $out"
# Raw frames on stdout for ffmpeg: whole frames of the asked size, the report on stderr.
"$bin" render "$tmp/a.hcavatar" --params "$tmp/p.hcrec" --display pipe --output-size 320x240 --background green \
  --pacing none > "$tmp/raw.bin" 2> "$tmp/pipe.log"
[ "$(stat -c %s "$tmp/raw.bin")" -eq $((320 * 240 * 3 * 20)) ] && grep -q '"rendered": 20' "$tmp/pipe.log" &&
  ok "pipe: 20 bgr24 frames of 320x240 on stdout" || bad "pipe: $(stat -c %s "$tmp/raw.bin") bytes; $(tail -3 "$tmp/pipe.log")"
if command -v ffmpeg >/dev/null; then
  ffmpeg -loglevel error -y -f rawvideo -pix_fmt bgr24 -video_size 320x240 -framerate 30 -i "$tmp/raw.bin" \
    -c:v libx264 -pix_fmt yuv420p "$tmp/pipe.mp4" && [ -s "$tmp/pipe.mp4" ] &&
    ok "the documented ffmpeg command takes the pipe's frames" || bad "ffmpeg on the pipe's frames"
fi
out=$("$bin" render "$tmp/a.hcavatar" --display pipe --output-size 641x480 2>&1 >/dev/null); rc=$?
[ $rc -ne 0 ] && grep -q "output-size" <<<"$out" && ok "odd output size refused" || bad "output size: $out"
out=$("$bin" render "$tmp/a.hcavatar" --display v4l2:/dev/headcast-none 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "v4l2loopback" <<<"$out" && ok "missing virtual camera refused with the set-up hint" || bad "v4l2: $out"
checks_summary "avatar cli"
