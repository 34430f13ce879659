#!/usr/bin/env bash
# headcast-rec on recordings the project makes, and python/headcast_files.py
# reading the same recordings and an avatar's manifest (numpy only).
set -u
bin_dir=$1
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
source "$src/tests/testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT
rec="$bin_dir/headcast-rec"
py=/usr/bin/python3

"$bin_dir/headcast-avatar" synth-params --frames 40 --out "$tmp/p.hcrec" >/dev/null
"$bin_dir/headcast-avatar" create --resolution 128 --out "$tmp/a.hcavatar" >/dev/null
"$rec" info "$tmp/p.hcrec" > "$tmp/info.json" && grep -q '"frames": 40' "$tmp/info.json" &&
  grep -q '"complete": true' "$tmp/info.json" && ok "info" || bad "info: $(cat "$tmp/info.json")"
for f in json csv npz; do
  "$rec" export "$tmp/p.hcrec" --format $f --out "$tmp/p.$f" 2>/dev/null && [ -s "$tmp/p.$f" ] && ok "export $f" || bad "export $f"
done
# export -> import -> export: the same parameters, value for value.
for f in json npz; do
  "$rec" import "$tmp/p.$f" --out "$tmp/back_$f.hcrec" 2>/dev/null &&
    "$rec" export "$tmp/back_$f.hcrec" --format json --out "$tmp/back_$f.json" 2>/dev/null &&
    cmp -s "$tmp/p.json" "$tmp/back_$f.json" && ok "round trip through $f: identical parameters" || bad "round trip $f"
done
out=$("$rec" import "$tmp/p.csv" --out "$tmp/x.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "cannot import" <<<"$out" && ok "a csv (not an import format) refused" || bad "import csv: $out"
sed 's/"fps": 30/"fps": -1/' "$tmp/p.json" > "$tmp/bad.json"
out=$("$rec" import "$tmp/bad.json" --out "$tmp/x.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "bad.json: cannot import" <<<"$out" && ok "a damaged export refused, naming the file" || bad "bad json: $out"
[ "$(grep -vc '^#' "$tmp/p.csv")" -eq 41 ] && ok "csv: a header row and 40 frames" || bad "csv rows"
"$rec" cut "$tmp/p.hcrec" --first-frame 10 --frames 15 --out "$tmp/c.hcrec" 2>/dev/null &&
  "$rec" info "$tmp/c.hcrec" | grep -q '"frames": 15' && ok "cut by frames" || bad "cut by frames"
"$rec" cut "$tmp/p.hcrec" --from 0.5 --to 1.0 --out "$tmp/t.hcrec" 2>/dev/null &&
  "$rec" info "$tmp/t.hcrec" | grep -q '"frames": 15' && ok "cut by time (0.5..1.0 s at 30 fps)" || bad "cut by time"
"$rec" concat "$tmp/c.hcrec" "$tmp/p.hcrec" --out "$tmp/j.hcrec" 2>/dev/null &&
  "$rec" info "$tmp/j.hcrec" > "$tmp/j.json" && grep -q '"frames": 55' "$tmp/j.json" &&
  grep -q '"times_going_back": 0' "$tmp/j.json" && grep -q '"sequence_gaps": 0' "$tmp/j.json" &&
  ok "concat continues times and sequence numbers" || bad "concat: $(cat "$tmp/j.json")"
out=$("$rec" cut "$tmp/p.hcrec" --from 2 --to 1 --out "$tmp/x.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "0 <= from < to" <<<"$out" && ok "inverted range refused" || bad "range: $out"
echo garbage > "$tmp/g.hcrec"
out=$("$rec" info "$tmp/g.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "not a headcast parameter recording" <<<"$out" && ok "foreign file refused" || bad "foreign: $out"
# Without --format, the file's extension says it; a --format against the extension is refused.
# (The npz by its zip signature: a zip's entries carry the time they were written.)
"$rec" export "$tmp/p.hcrec" --out "$tmp/q.npz" 2>/dev/null && [ "$(head -c 2 "$tmp/q.npz")" = PK ] &&
  "$rec" export "$tmp/p.hcrec" --out "$tmp/q.data" 2>/dev/null && cmp -s "$tmp/p.json" "$tmp/q.data" &&
  ok "export: the format from the file's extension (.npz), json for others" || bad "export by extension"
out=$("$rec" export "$tmp/p.hcrec" --format json --out "$tmp/r.npz" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "would not be the npz its name says" <<<"$out" && [ ! -e "$tmp/r.npz" ] &&
  ok "export: --format json into a .npz refused" || bad "export format against extension: $out"
out=$("$rec" export "$tmp/p.hcrec" --format xml --out "$tmp/p.xml" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "json, csv or npz" <<<"$out" && ok "unknown format refused" || bad "format: $out"
head -c $(( $(stat -c %s "$tmp/p.hcrec") - 7 )) "$tmp/p.hcrec" > "$tmp/cut.hcrec"
"$rec" info "$tmp/cut.hcrec" | grep -q '"frames": 39' && ok "a record cut short: the whole frames before it" || bad "cut file"

# The Python module reads the same numbers the C++ tools export.
if $py -c "import numpy" 2>/dev/null; then
  out=$(PYTHONPATH="$src/python" $py - "$tmp" <<'PY' 2>&1
import json, sys
import numpy as np
import headcast_files as hf
tmp = sys.argv[1]
r = hf.read_recording(f"{tmp}/p.hcrec")
exported = json.load(open(f"{tmp}/p.json"))
npz = np.load(f"{tmp}/p.npz")
assert len(r) == 40 and r.expression.shape == (40, exported["header"]["num_expression"])
assert r.header["head_model_fingerprint"] == exported["header"]["head_model_fingerprint"]
assert np.array_equal(r.expression, npz["expression"]) and np.array_equal(r.capture_time_s, npz["capture_time_s"])
for g in hf.GROUPS:
    assert np.array_equal(getattr(r, g), npz[g]), g
    assert np.allclose(getattr(r, g), [f[g] for f in exported["frames"]], atol=1e-6), g
assert np.array_equal(r.sequence, [f["sequence"] for f in exported["frames"]])
assert np.allclose(r.header["subject"]["shape"], npz["shape"])
cut = hf.read_recording(f"{tmp}/cut.hcrec")
assert len(cut) == 39 and "cut short" in cut.cut, cut.cut
try:
    hf.read_recording(f"{tmp}/g.hcrec")
    raise SystemExit("foreign recording read")
except hf.FormatError as e:
    assert "not a headcast parameter recording" in str(e)
m = hf.read_avatar_manifest(f"{tmp}/a.hcavatar")
assert m["format"] == "headcast-avatar", m["format"]
try:
    hf.read_avatar_manifest(f"{tmp}/p.hcrec")
    raise SystemExit("a recording read as an avatar")
except hf.FormatError:
    pass
print("python ok")
PY
)
  grep -q "python ok" <<<"$out" && ok "python/headcast_files.py reads recordings, cut files and manifests" || bad "python: $out"
else
  bad "python3-numpy is missing (deploy/setup.sh installs it)"
fi
# --config and global flags work in every program, also after a subcommand; unknown keys are refused.
printf 'log = "warn"\n' > "$tmp/ok.toml"
printf 'lgo = "warn"\n' > "$tmp/typo.toml"
"$rec" --config "$tmp/ok.toml" info "$tmp/p.hcrec" > /dev/null 2>&1 && "$rec" info "$tmp/p.hcrec" --log warn > /dev/null 2>&1 &&
  ok "--config FILE and --log after the subcommand are accepted" || bad "config / global flag after subcommand"
out=$("$rec" --config "$tmp/typo.toml" info "$tmp/p.hcrec" 2>&1)
[ $? -ne 0 ] && grep -q "lgo" <<<"$out" && ok "a misspelt config key is refused, named" || bad "config typo: $out"
checks_summary "headcast-rec"
