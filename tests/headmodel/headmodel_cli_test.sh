#!/usr/bin/env bash
# headcast-headmodel as a user runs it: convert, summarise, render; bad files refused clearly.
set -u
bin=$1
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT

"$bin" convert builtin --out "$tmp/builtin.npz" >/dev/null && ok "convert builtin" || bad "convert builtin"
"$bin" summary "$tmp/builtin.npz" | grep -q "expressions: smile" && ok "summary lists expressions" || bad "summary"
"$bin" render "$tmp/builtin.npz" --view both --size 128 --landmarks --expression smile=1 --jaw 10 --out "$tmp/r.png" 2>/dev/null
head -c 8 "$tmp/r.png" | od -An -c | grep -q "P   N   G" && ok "render writes a PNG" || bad "render PNG"
"$bin" render builtin --sweep jaw --size 96 --video "$tmp/s.mp4" 2>/dev/null && [ -s "$tmp/s.mp4" ] && ok "render writes an MP4 sweep" || bad "sweep"
out=$("$bin" render builtin --expression frown=1 --out "$tmp/x.png" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "no expression component 'frown'" <<<"$out" && ok "unknown expression refused" || bad "unknown expression: $out"
out=$("$bin" render builtin --expression smile=1x --out "$tmp/x.png" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "\-\-expression smile: '1x' is not a number" <<<"$out" && ok "a bad number is named" || bad "bad number: $out"
head -c 5000 "$tmp/builtin.npz" > "$tmp/cut.npz"
out=$("$bin" summary "$tmp/cut.npz" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "cut.npz" <<<"$out" && ok "truncated model refused by name" || bad "truncated: $out"
out=$("$bin" summary "$tmp/none.npz" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "no such file" <<<"$out" && ok "missing model refused" || bad "missing: $out"
checks_summary "headmodel cli"
