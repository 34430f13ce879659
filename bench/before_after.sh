#!/usr/bin/env bash
# Behaviour of two builds side by side, in one run, on the same inputs: for
# refactors that must change nothing a user sees.
#   bench/before_after.sh BEFORE_BIN AFTER_BIN OUT [--general G.hcavatar] [--iterations N] [--video V] [--ict DIR]
# BEFORE_BIN / AFTER_BIN: the bin/ folders of the two builds (copy one away
# before rebuilding). Measures, each build on the same data:
#   tracking on the video with ICT-FaceKit (headcast-track --calibrate, one core: taskset -c 0):
#     frames fitted, landmark error, ms per frame;
#   the codec's bits per frame (headcast-bench codec);
#   the avatar's frame rate at 256² (headcast-bench render, 2 threads' worth of cores);
#   a talking-head avatar's test PSNR/SSIM at 256²: prep, N fine-tune steps from the
#     same general model and seed, then eval — each build end to end, and the
#     before build's avatar evaluated by the after build too (the eval path alone).
# Writes OUT/before_after.{json,md} and prints the table.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${HEADCAST_PYTHON:-/usr/bin/python3}
data=${HEADCAST_DATA:-$root/../shared/data}
[ $# -ge 3 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
before=$(cd "$1" && pwd) after=$(cd "$2" && pwd) out=$3; shift 3
command="bench/before_after.sh BEFORE_BIN AFTER_BIN OUT $*"  # no machine paths in what is written
iterations=2000 name=before_after
source "$root/bench/person_args.sh"
parse_person_args "$@"
mkdir -p "$out"
out=$(cd "$out" && pwd)
step() { echo "== $*" >&2; }
run() {  # run LOG COMMAND...
  local log=$1; shift
  "$@" > "$out/$log" 2>&1 || { echo "before_after: failed, see $out/$log" >&2; exit 1; }
}

step "ICT-FaceKit -> npz"
run convert.log "$after/headcast-headmodel" convert ict --folder "$ict" --out "$out/ict.npz"
model=$out/ict.npz
if [ -z "$general" ]; then
  step "general model (128², 4000 steps, after build)"
  general=$out/general128.hcavatar
  run pretrain.log "$after/headcast-train" pretrain --head-model "$model" --resolution 128 --iterations 4000 \
    --processes 2 --out "$general"
fi
for which in before after; do
  bin=${!which}
  step "$which: tracking (one core)"
  run "track_$which.log" taskset -c 0 "$bin/headcast-track" --input "$video" --head-model "$model" --calibrate \
    --out "$out/track_$which.hcrec" --json "$out/track_$which.json"
  step "$which: codec"
  run "codec_$which.log" "$bin/headcast-bench" codec --json "$out/codec_$which.json"
  step "$which: render 256²"
  run "render_$which.log" "$bin/headcast-bench" render --resolution 256 --repeats 100 --json "$out/render_$which.json"
  step "$which: prep"
  rm -rf "$out/ds_$which"
  run "prep_$which.log" "$bin/headcast-train" prep --input "$video" --head-model "$model" --out "$out/ds_$which" \
    --resolutions 256 --test-frames 150
  step "$which: fine-tune at 256² ($iterations steps)"
  run "subject_$which.log" "$bin/headcast-train" subject --head-model "$model" --general "$general" \
    --data "$out/ds_$which" --resolution 256 --processes 2 --iterations "$iterations" --z-augmentation 0 \
    --out "$out/avatar_$which.hcavatar"
  step "$which: eval"
  run "eval_$which.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$which.hcavatar" \
    --data "$out/ds_$which" --out "$out/eval_$which" --orbit-frames 0
done
step "after's eval of before's avatar"
run eval_cross.log "$after/headcast-train" eval --head-model "$model" --avatar "$out/avatar_before.hcavatar" \
  --data "$out/ds_before" --out "$out/eval_cross" --orbit-frames 0

"$python" - "$out" "$command" "$iterations" <<'EOF'
import json, os, sys
out, command, iterations = sys.argv[1:]
def load(name): return json.load(open(os.path.join(out, name)))
rows = []
for which in ("before", "after"):
    t, c, r = load(f"track_{which}.json"), load(f"codec_{which}.json"), load(f"render_{which}.json")
    e = load(f"eval_{which}/eval.json")["eval"]
    rows.append({"build": which, "fitted": f"{t['fitted_frames']}/{t['frames']}",
                 "landmark_error_iod": t["landmark_error_iod_mean"], "track_ms_median": t["ms_per_frame_median"],
                 "codec_bits_per_frame": c["bits_per_frame_mean"], "render_fps_256": r["fps_median"],
                 "test_psnr_db": e["psnr_db"], "test_ssim": e["ssim"]})
cross = load("eval_cross/eval.json")["eval"]
result = {"command": command, "iterations": int(iterations), "rows": rows,
          "before_avatar_by_after_eval": {"test_psnr_db": cross["psnr_db"], "test_ssim": cross["ssim"]}}
json.dump(result, open(os.path.join(out, "before_after.json"), "w"), indent=2)
L = [f"Made by `{command}` ({iterations} fine-tune steps at 256², same general model and seed).", "",
     "| build | fitted | landmark error (IOD) | track ms/frame (1 core) | codec bits/frame | render fps 256² | test PSNR (dB) | test SSIM |",
     "|---|---|---|---|---|---|---|---|"]
for x in rows:
    L.append(f"| {x['build']} | {x['fitted']} | {x['landmark_error_iod']:.4f} | {x['track_ms_median']:.2f} | "
             f"{x['codec_bits_per_frame']:.1f} | {x['render_fps_256']:.1f} | {x['test_psnr_db']:.3f} | "
             f"{x['test_ssim']:.4f} |")
L += ["", f"The before build's avatar, evaluated by the after build: {cross['psnr_db']:.3f} dB, SSIM {cross['ssim']:.4f}."]
open(os.path.join(out, "before_after.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
EOF
