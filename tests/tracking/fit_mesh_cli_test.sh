#!/usr/bin/env bash
# headcast-fit-mesh as a user runs it: export a posed model mesh, fit it back
# (analytic and black-box), and bad meshes refused with the reason.
set -u
bin=$1
python=${2:-/usr/bin/python3}
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT

"$bin/headcast-headmodel" export builtin --out "$tmp/head.obj" --shape 0=1.2 --shape 2=-0.8 --expression smile=0.6 \
  --jaw 6 --landmarks-out "$tmp/lmk.json" > /dev/null && ok "export a posed mesh" || bad "export"
shape_near() {  # file index value tolerance
  "$python" -c "import json,sys; j=json.load(open('$1')); sys.exit(0 if abs(j['shape'][$2]-($3)) < $4 else 1)"
}
"$bin/headcast-fit-mesh" --mesh "$tmp/head.obj" --out "$tmp/p.json" --fitted-mesh "$tmp/fit.ply" > "$tmp/s.json" &&
  shape_near "$tmp/p.json" 0 1.2 0.01 && shape_near "$tmp/p.json" 2 -0.8 0.01 && [ -s "$tmp/fit.ply" ] &&
  ok "fit recovers the shape it was made with" || bad "fit: $(cat "$tmp/s.json")"
"$bin/headcast-fit-mesh" --mesh "$tmp/head.obj" --out "$tmp/bb.json" --black-box --fit shape > /dev/null &&
  shape_near "$tmp/bb.json" 0 1.2 0.1 && ok "black-box mode fits too" || bad "black box"
"$bin/headcast-fit-mesh" --mesh "$tmp/fit.ply" --out "$tmp/o.json" --topology other --landmarks "$tmp/lmk.json" \
  --rounds 3 > /dev/null && grep -q '"same_topology": false' "$tmp/o.json" && ok "other-topology mode with landmarks" ||
  bad "other topology"
# Centimetres: detected, then accepted with --unit cm.
awk '$1 == "v" { printf "v %f %f %f\n", $2 * 100, $3 * 100, $4 * 100; next } { print }' "$tmp/head.obj" > "$tmp/cm.obj"
out=$("$bin/headcast-fit-mesh" --mesh "$tmp/cm.obj" --out "$tmp/x.json" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "centimetres" <<<"$out" && ok "centimetres detected" || bad "cm: $out"
"$bin/headcast-fit-mesh" --mesh "$tmp/cm.obj" --out "$tmp/cm.json" --unit cm > /dev/null &&
  shape_near "$tmp/cm.json" 0 1.2 0.01 && ok "--unit cm fits" || bad "--unit cm"
head -c 20000 "$tmp/head.obj" > "$tmp/cut.obj"
out=$("$bin/headcast-fit-mesh" --mesh "$tmp/cut.obj" --out "$tmp/x.json" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "cut.obj: line [0-9]*:" <<<"$out" && ok "truncated file refused with the line" || bad "cut: $out"
awk '$1 != "f" || NR % 2 == 0' "$tmp/head.obj" > "$tmp/half.obj"  # the same vertices, half the faces
out=$("$bin/headcast-fit-mesh" --mesh "$tmp/half.obj" --out "$tmp/x.json" --topology same 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "same-topology fit asked for" <<<"$out" && ok "wrong topology refused" || bad "topology: $out"
out=$("$bin/headcast-fit-mesh" --mesh "$tmp/half.obj" --out "$tmp/x.json" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "landmarks" <<<"$out" && ok "other topology without landmarks says what it needs" || bad "$out"
printf 'v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n' > "$tmp/nan.obj"
out=$("$bin/headcast-fit-mesh" --mesh "$tmp/nan.obj" --out "$tmp/x.json" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "non-finite" <<<"$out" && ok "NaN vertex refused" || bad "nan: $out"
: > "$tmp/empty.ply"
out=$("$bin/headcast-fit-mesh" --mesh "$tmp/empty.ply" --out "$tmp/x.json" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "not a PLY" <<<"$out" && ok "empty file refused" || bad "empty: $out"
# The identity feeds the tracker.
"$bin/headcast-track" --help | grep -q -- "--identity-from" && ok "headcast-track takes --identity-from" || bad "track flag"
checks_summary "fit-mesh cli"
