#!/usr/bin/env bash
# Runs every headcast-bench suite, the bandwidth runs, the loopback demo and the
# x264 comparison, then writes bench/REPORT.md (+ bench/results/*.json, PNGs).
#   bench/run_all.sh [--quick] [--dataset DS --avatar A.hcavatar --head-model M.npz]
# --dataset/--avatar: a prepared dataset and its subject's avatar for the codec
# comparison and training throughput on real frames (e.g. talking_d9 prepared with
# ICT-FaceKit); without them those rows say so. --quick: fewer repeats, 20 s links.
# netns links need root (tbf rate limits); otherwise only loopback runs.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=$root/build/bin
python=${HEADCAST_PYTHON:-/usr/bin/python3}
res=$root/bench/results
quick=0 dataset="" avatar="" head_model=builtin
command="bench/run_all.sh $*"
while [ $# -gt 0 ]; do
  case $1 in
    --quick) quick=1; shift ;;
    --dataset) dataset=$2; shift 2 ;;
    --avatar) avatar=$2; shift 2 ;;
    --head-model) head_model=$2; shift 2 ;;
    *) echo "run_all: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$res"
work=$(mktemp -d)  # derived data (the converted ICT model) stays out of the repository
trap 'rm -rf "$work"' EXIT
repeats=200 link_s=60 train_iterations=30
[ "$quick" = 1 ] && repeats=40 link_s=20 train_iterations=10
step() { echo "== $*" >&2; }
bench() { local name=$1; shift; step "headcast-bench $*"; "$bin/headcast-bench" "$@" --json "$res/$name.json" > /dev/null; }

bench headmodel headmodel --repeats $repeats
bench raster raster --repeats $((repeats / 4 + 1))
for r in 128 256 512; do bench "render_$r" render --resolution $r --repeats $((repeats / 2)); done
bench render_256_vs_headnerf render --resolution 256 --repeats $((repeats / 4)) --compare-headnerf
bench codec codec
for r in 128 256; do
  if [ -n "$dataset" ] && [ -d "$dataset/$r" ]; then
    bench "train_$r" train --resolution $r --iterations $train_iterations --head-model "$head_model" --data "$dataset"
  else
    bench "train_$r" train --resolution $r --iterations $train_iterations
  fi
done
data=${HEADCAST_DATA:-$root/../shared/data}
if [ -f "$data/video/talking_d9.mp4" ] && [ -d "$data/head-models/ict-facekit" ]; then
  "$bin/headcast-headmodel" convert ict --folder "$data/head-models/ict-facekit" --out "$work/ict.npz" > /dev/null
  step "track (one core)"
  taskset -c 0 "$bin/headcast-bench" track --video "$data/video/talking_d9.mp4" --head-model "$work/ict.npz" \
    --repeats 100000 --json "$res/track.json" > /dev/null
else
  echo "{\"skipped\": \"no $data/video/talking_d9.mp4 or ICT-FaceKit\"}" > "$res/track.json"
fi
bench meshfit meshfit --trials $([ "$quick" = 1 ] && echo 1 || echo 3)
bench rgbd rgbd --frames $([ "$quick" = 1 ] && echo 6 || echo 30)

# Links: unconstrained loopback, and tbf-limited veth links when root.
step "netlab loopback"
"$root/deploy/netlab/netlab.sh" --mode loopback --duration $link_s --out "$res/netlab_loopback" > /dev/null
for rate in 8 16 32; do
  if [ "$(id -u)" -eq 0 ]; then
    step "netlab $rate kbit/s"
    "$root/deploy/netlab/netlab.sh" --mode netns --rate $rate --duration $link_s --out "$res/netlab_${rate}kbit" > /dev/null
  fi
done

# The loopback demo: glass-to-glass latency with sender and receiver on this machine.
step "demo (loopback session)"
"$root/deploy/demo.sh" --no-setup --display offscreen --out "$res/demo" > /dev/null

# x264 against headcast on the same test frames.
if [ -n "$dataset" ] && [ -n "$avatar" ]; then
  step "x264 comparison"
  "$bin/headcast-train" eval --head-model "$head_model" --avatar "$avatar" --data "$dataset" --out "$work/eval" \
    --write-frames --orbit-frames 0 > /dev/null
  cp "$work/eval/eval.json" "$res/eval.json"
  points=(--headcast "$("$python" -c "import json; print(json.load(open('$res/netlab_loopback/netlab.json'))['uplink_kbps_on_wire'])"):unconstrained, 30 fps")
  for rate in 8 16 32; do
    f=$res/netlab_${rate}kbit/netlab.json
    [ -f "$f" ] && points+=(--headcast "$("$python" -c "import json; print(json.load(open('$f'))['uplink_kbps_on_wire'])"):$rate kbit/s link")
  done
  "$python" "$root/bench/x264_compare.py" --frames "$work/eval/frames" "${points[@]}" --out "$res/x264.json" \
    --plot "$res/x264.png" > /dev/null
else
  echo '{"skipped": "give --dataset and --avatar"}' > "$res/x264.json"
fi
"$python" "$root/bench/make_report.py" --results "$res" --command "$command" --out "$root/bench/REPORT.md"
# Committed results name no path of this machine.
"$python" "$root/bench/strip_machine_paths.py" --root "$root" --data "$data" "$res" "$root/bench/REPORT.md"
echo "wrote $root/bench/REPORT.md"
