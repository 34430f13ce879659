#!/usr/bin/env bash
# Sets headcast up, then runs its main job on the embedded default.
# Until the end-to-end session exists, that is: the built-in head rendered
# through a head-turn, jaw and expression sweep to a video, plus preview PNGs.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
"$root/deploy/setup.sh"
out=${HEADCAST_DEMO_OUT:-$root/out/demo}
mkdir -p "$out"
bin=$root/build/bin
"$bin/headcast-headmodel" summary builtin
"$bin/headcast-headmodel" render builtin --view both --landmarks --out "$out/builtin_front_side.png"
"$bin/headcast-headmodel" render builtin --view grid --out "$out/builtin_components.png"
"$bin/headcast-headmodel" render builtin --sweep all --size 512 --video "$out/builtin_sweep.mp4"
echo
echo "headcast demo: wrote"
echo "  $out/builtin_sweep.mp4        (head turn, jaw, every expression component; 30 fps)"
echo "  $out/builtin_front_side.png   (front and side view with the 68 landmarks)"
echo "  $out/builtin_components.png   (every expression at +1 and shape component at +2)"
