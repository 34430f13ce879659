#!/usr/bin/env bash
# headcast-train pretrain as a user runs it: killed with -9 mid-run, resumed,
# it finishes and its loss log has every step once.
set -u
bin=$1
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'kill -9 "${pid:-}" 2>/dev/null; rm -rf "$tmp"' EXIT
common=(pretrain --resolution 128 --batch 1 --eval 1 --checkpoint-dir "$tmp/ckpt" --checkpoint-every 4
      --log-csv "$tmp/loss.csv" --out "$tmp/a.hcavatar")
args=("${common[@]}" --iterations 200)
"$bin/headcast-train" "${args[@]}" > /dev/null 2>&1 &
pid=$!
for _ in $(seq 600); do
  [ -s "$tmp/ckpt/LATEST" ] && break
  sleep 0.05
done
kill -9 "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; pid=
at=$(cat "$tmp/ckpt/LATEST" 2>/dev/null)
[ -n "$at" ] && [ ! -e "$tmp/a.hcavatar" ] && ok "killed with -9 after checkpoint $at" || bad "no checkpoint before the kill ($at)"
"$bin/headcast-train" "${args[@]}" --resume > "$tmp/out.json" 2> "$tmp/err.log" && [ -s "$tmp/a.hcavatar" ] &&
  ok "resumed and finished" || bad "resume: $(tail -3 "$tmp/err.log")"
rows=$(tail -n +2 "$tmp/loss.csv" | cut -d, -f1 | sort -n | uniq | wc -l)
all=$(tail -n +2 "$tmp/loss.csv" | wc -l)
[ "$rows" -eq 200 ] && [ "$all" -eq 200 ] && ok "the loss log has each of the 200 steps once" || bad "log: $rows unique of $all rows"
echo "garbage" > "$tmp/ckpt/$(cat "$tmp/ckpt/LATEST")/state.json"
out=$("$bin/headcast-train" "${common[@]}" --iterations 240 --resume 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "cannot resume" <<<"$out" && ok "corrupt checkpoint refused by name" || bad "corrupt: $out"
checks_summary "train cli"
