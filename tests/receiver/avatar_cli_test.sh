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
out=$("$bin" render "$tmp/a.hcavatar" --params "$tmp/p.hcrec" --display offscreen --video "$tmp/v.mp4" --unpaced \
      --orbit 30 --transfer "$tmp/q.hcrec" --stats-json "$tmp/s.json" 2>&1)
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
checks_summary "avatar cli"
