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
kept=$(cat "$tmp/ckpt/LATEST")
out=$("$bin/headcast-train" "${common[@]}" --iterations 8 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "holds a checkpoint of an earlier run" <<<"$out" && [ "$(cat "$tmp/ckpt/LATEST")" = "$kept" ] &&
  [ -d "$tmp/ckpt/$kept" ] && ok "a new run without --resume leaves the earlier checkpoint alone" || bad "no resume: $out"
out=$("$bin/headcast-train" pretrain --resolution 128 --iterations 4 --checkpoint-dir "$tmp/no-such-ckpt" --resume \
  --out "$tmp/b.hcavatar" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "no checkpoint folder" <<<"$out" && ok "--resume on a missing folder is refused" || bad "resume typo: $out"
# A network size given to a fine-tune is refused, not dropped (the general model's network is kept).
out=$("$bin/headcast-train" subject --general "$tmp/a.hcavatar" --data "$tmp/no-dataset" --out "$tmp/x.hcavatar" \
  --renderer-channels 48,24,8 \
  2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "renderer-channels sizes a new network" <<<"$out" && ok "--renderer-channels on a fine-tune is refused" ||
  bad "architecture flag on a fine-tune: $out"
# Rank 0 killed with -9: its copy must not wait out Gloo's 300 s timeout.
"$bin/headcast-train" pretrain --resolution 128 --batch 1 --iterations 100000 --processes 2 --out "$tmp/c.hcavatar" \
  > /dev/null 2>&1 &
pid=$!
for _ in $(seq 300); do child=$(pgrep -P "$pid" | head -1); [ -n "$child" ] && break; sleep 0.1; done
sleep 2
kill -9 "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; pid=
gone=no
for _ in $(seq 100); do kill -0 "$child" 2>/dev/null || { gone=yes; break; }; sleep 0.1; done
[ -n "$child" ] && [ $gone = yes ] && ok "a copy rank ends with its killed rank 0" || { bad "copy rank $child still running"; kill -9 "$child" 2>/dev/null; }
echo "garbage" > "$tmp/ckpt/$(cat "$tmp/ckpt/LATEST")/state.json"
out=$("$bin/headcast-train" "${common[@]}" --iterations 240 --resume 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "cannot resume" <<<"$out" && ok "corrupt checkpoint refused by name" || bad "corrupt: $out"
checks_summary "train cli"
