#!/usr/bin/env bash
# The Debian package as a user gets it: `cpack -G DEB` in the build folder; its
# control (the runtime libraries found by dpkg-shlibdeps, plus the BLAS, dlib's
# predictor and ffmpeg); its files (programs, shipped models with the ICT-FaceKit
# licence, the systemd unit running the installed program, example configs,
# licences); then, unpacked into a scratch root, the installed receiver starts
# with the installed demo avatar and shows what a sender sends, and the
# installed trainer finds the shipped models beside it.
set -u
build=$1 python=${2:-/usr/bin/python3}
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'kill "${rx:-}" 2>/dev/null; rm -rf "$tmp"' EXIT
json() { "$python" -c "import json,sys; j=json.load(open('$1')); print($2)" 2>/dev/null; }

(cd "$build" && cpack -G DEB -B "$tmp/pkg" > "$tmp/cpack.log" 2>&1)
deb=$(ls "$tmp"/pkg/headcast_*.deb 2>/dev/null | head -1)
[ -n "$deb" ] && ok "cpack made $(basename "$deb") ($(($(stat -c %s "$deb") / 1048576)) MB)" ||
  { bad "cpack: $(tail -5 "$tmp/cpack.log")"; checks_summary package_test; exit; }

depends=$(dpkg-deb -f "$deb" Depends)
missing=""
for d in libtorch libopencv-core libgrpc++ libprotobuf libglfw3 libopenblas0-pthread libdlib-data ffmpeg; do
  grep -q "$d" <<<"$depends" || missing="$missing $d"
done
[ -z "$missing" ] && ok "depends on its runtime libraries, the BLAS, the predictor and ffmpeg" ||
  bad "Depends lacks$missing: $depends"

contents=$(dpkg-deb -c "$deb")
missing=""
for f in usr/bin/headcast-receiver usr/bin/headcast-sender usr/bin/headcast-train usr/bin/headcast-track \
  usr/share/headcast/models/ict_facekit.npz usr/share/headcast/models/ict_facekit.LICENSE \
  usr/share/headcast/models/ict_general.hcavatar usr/share/headcast/models/demo_avatar.hcavatar \
  usr/share/headcast/examples/receiver.toml usr/lib/systemd/system/headcast-receiver.service \
  usr/share/doc/headcast/LICENSE usr/share/doc/headcast/THIRD_PARTY_NOTICES.md; do
  grep -q " \./$f$" <<<"$contents" || missing="$missing $f"
done
[ -z "$missing" ] && ok "holds the programs, the shipped models, the unit, the examples and the licences" ||
  bad "missing from the package:$missing"

dpkg-deb -x "$deb" "$tmp/root"
grep -q "^ExecStart=/usr/bin/headcast-receiver " "$tmp/root/usr/lib/systemd/system/headcast-receiver.service" &&
  grep -q "/usr/share/headcast/models/demo_avatar.hcavatar" "$tmp/root/usr/share/headcast/examples/receiver.toml" &&
  ok "the unit runs the installed receiver; the example config names the installed demo avatar" ||
  bad "unit or example config do not point at the installation"

version=$(dpkg-deb -f "$deb" Version)
wrong=""
for program in "$tmp/root/usr/bin"/headcast-*; do
  [ "$("$program" --version 2>&1)" = "headcast $version" ] || wrong="$wrong $(basename "$program")"
done
[ -z "$wrong" ] && ok "every installed program answers --version with the package's version ($version)" ||
  bad "--version wrong for:$wrong"

port=$((20000 + $$ % 20000))
"$tmp/root/usr/bin/headcast-receiver" --listen "127.0.0.1:$port" --plaintext --allow-no-token --display none \
  --avatar "demo=$tmp/root/usr/share/headcast/models/demo_avatar.hcavatar" --json "$tmp/rx.json" \
  > /dev/null 2> "$tmp/rx.log" &
rx=$!
wait_for "$tmp/rx.log" listening || bad "the installed receiver never listened"
"$tmp/root/usr/bin/headcast-sender" --target "127.0.0.1:$port" --plaintext --avatar-id demo --synthetic 30 \
  > /dev/null 2> "$tmp/tx.log"
sleep 0.5
kill -INT "$rx"; wait "$rx"; rx=
[ "$(json "$tmp/rx.json" "j['frames_received']")" = 30 ] && [ "$(json "$tmp/rx.json" "j['rendered'] > 0")" = True ] &&
  ok "the installed receiver, with the installed demo avatar, received 30 frames and showed them" ||
  bad "installed receiver: $(tail -3 "$tmp/rx.log") $(tail -2 "$tmp/tx.log")"

out=$("$tmp/root/usr/bin/headcast-train" create --input "$tmp/none.mp4" --out "$tmp/me.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "none.mp4" <<<"$out" && ! grep -q "shipped model" <<<"$out" &&
  ok "the installed trainer finds the shipped models in share/headcast/models (and names the missing input)" ||
  bad "installed create: $out"

checks_summary package_test
