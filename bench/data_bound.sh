#!/usr/bin/env bash
# How a clip's held-out figures depend on what its training frames show: one
# prepared dataset (ICT-FaceKit, the last 150 frames held out, as
# bench/four_clips.sh prepares it), fine-tuned with the table's settings on
# the first N fitted frames for each N asked, and scored by headcast-train eval
# on the same 150 held-out frames, with and without the sender's outline.
# "all" trains on every fitted frame, the held-out ones included: the picture
# the avatar draws of those frames once it has seen them (the fit, the masks
# and the networks' capacity), against which the default row's shortfall is
# what the training frames do not show. Each row's held-out frames are also
# scored in blocks of 50, so a stretch beyond the training frames shows apart.
#   bench/data_bound.sh OUT [--clip d3] [--train "102 204 all"] [--general G.hcavatar]
#       [--iterations N (3000)] [--ict DIR] [--reuse]
# Writes OUT/data_bound_CLIP.json and prints the table.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/script_start.sh"
name=data_bound clip=d3 trains="102 204 all" iterations=3000 general="" ict=$data/head-models/ict-facekit reuse=0
while [ $# -gt 0 ]; do
  case $1 in
    --clip) clip=$2; shift 2 ;;
    --train) trains=$2; shift 2 ;;
    --general) general=$2; shift 2 ;;
    --iterations) iterations=$2; shift 2 ;;
    --ict) ict=$2; shift 2 ;;
    --reuse) reuse=1; shift ;;
    *) echo "$name: unknown option $1" >&2; exit 2 ;;
  esac
done
# The call as the results record it, the list of rows quoted as it must be given.
command="bench/data_bound.sh ${out_name:-OUT} --clip $clip --train \"$trains\" --iterations $iterations"
[ -n "$general" ] && command+=" --general $general"
[ "$reuse" = 1 ] && command+=" --reuse"
[ -d "$ict" ] || { echo "$name: no ICT-FaceKit folder $ict" >&2; exit 2; }
video=$data/video/talking_$clip.mp4
[ -f "$video" ] || { echo "$name: no video $video" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
source "$root/bench/avatar_runs.sh"
ict_and_general
ds=$out/ds_$clip
if [ "$reuse" = 0 ] || [ ! -f "$ds/dataset.json" ]; then
  step "$clip: prep"
  rm -rf "$ds"
  prep_clip "prep_$clip.log" "$video" "$ds"
fi
for n in $trains; do
  tag=${clip}_train$n
  if [ "$reuse" = 1 ] && [ -f "$out/eval_$tag/eval.json" ] && [ -f "$out/eval_outline_$tag/eval.json" ]; then
    step "$tag: reusing OUT's avatar and evaluations"
    continue
  fi
  # The same crops, masks and fits; only the split differs (the dataset's
  # training split is its first `train` fitted frames).
  variant=$out/ds_$tag
  rm -rf "$variant" && mkdir -p "$variant"
  for f in "$ds"/*; do [ "$(basename "$f")" = dataset.json ] || ln -s "$f" "$variant/"; done
  "$python" - "$ds/dataset.json" "$variant/dataset.json" "$n" <<'EOF'
import json, sys
m = json.load(open(sys.argv[1]))
n = m["frames_fitted"] if sys.argv[3] == "all" else int(sys.argv[3])
if not 1 <= n <= m["frames_fitted"]:
    sys.exit(f"data_bound: {n} training frames of {m['frames_fitted']} fitted")
m["split"].update(train=n, test=m["frames_fitted"] - n)
json.dump(m, open(sys.argv[2], "w"), indent=1)
EOF
  step "$tag: fine-tune ($iterations steps)"
  fine_tune_clip "subject_$tag.log" "$general" "$variant" "$out/avatar_$tag.hcavatar" "$iterations"
  step "$tag: eval on the held-out frames"
  run "eval_$tag.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$tag.hcavatar" \
    --data "$ds" --out "$out/eval_$tag" --orbit-frames 0 --no-landmarks
  run "eval_outline_$tag.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$tag.hcavatar" \
    --data "$ds" --out "$out/eval_outline_$tag" --orbit-frames 0 --no-landmarks --outline-bins 12
done

"$python" - "$out" "$command" "$clip" $trains <<'EOF'
import csv, json, os, sys
out, command, clip, trains = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
rows = []
for n in trains:
    row = {"train_frames": n}
    for key, folder in (("default", f"eval_{clip}_train{n}"), ("with_outline", f"eval_outline_{clip}_train{n}")):
        e = json.load(open(os.path.join(out, folder, "eval.json")))["eval"]
        frames = [(int(r["frame"]), float(r["psnr"]), float(r["ssim"]))
                  for r in csv.DictReader(open(os.path.join(out, folder, "per_frame.csv")))]
        blocks = []
        for i in range(0, len(frames), 50):
            b = frames[i:i + 50]
            blocks.append({"frames": f"{b[0][0]}-{b[-1][0]}", "psnr_db": sum(x[1] for x in b) / len(b),
                           "ssim": sum(x[2] for x in b) / len(b)})
        row[key] = {"psnr_db": e["psnr_db"], "ssim": e["ssim"], "frames": e["frames"], "blocks": blocks}
    rows.append(row)
json.dump({"command": command, "clip": f"talking_{clip}", "rows": rows}, open(os.path.join(out, f"data_bound_{clip}.json"), "w"), indent=2)
print(f"Made by `{command}`: talking_{clip}, scored on the same 150 held-out frames; SSIM per block of 50 held-out frames.\n")
names = [b["frames"] for b in rows[0]["default"]["blocks"]]
print("| training frames | PSNR / SSIM | with the outline | with the outline, SSIM by block " + " / ".join(names) + " |")
print("|---|---|---|---|")
for r in rows:
    d, o = r["default"], r["with_outline"]
    print(f"| {r['train_frames']} | {d['psnr_db']:.3f} / {d['ssim']:.4f} | {o['psnr_db']:.3f} / {o['ssim']:.4f} | "
          + " / ".join(f"{b['ssim']:.4f}" for b in o["blocks"]) + " |")
EOF
