#!/usr/bin/env bash
# Makes the shipped models with the project's own pipeline:
#   builtin (from nothing but the built-in head model, ~40 min on 2 cores):
#     1. the general model for the built-in head (headcast-train pretrain);
#     2. a synthetic demo subject: a talking head with its own identity rendered
#        by headcast-headmodel as an RGB-D sequence (colour + depth, as a
#        ZED2-style camera sees it); its first frames train the avatar, its
#        last frames are the demo's input (never trained on; deploy/demo.sh
#        renders them again from models/demo/subject.json);
#     3. their reports, logs and plots; the avatar is made by `headcast-train create`.
#   ict (from the ICT-FaceKit folder, ~17 min on 2 cores): what `headcast-train
#     create` starts from, so a real person's avatar needs no download:
#     1. ICT-FaceKit converted compactly (int16 bases, 5 µm a step, its parts
#        painted; MIT, its licence beside it as ict_facekit.LICENSE);
#     2. its general model in two stages, as measured (bench/results/
#        fidelity_ablation.md, session 63): pretrained on unpainted renders with
#        head-frame samples, then continued on painted renders with canonical
#        samples and the covered parts apart (the settings of a person's
#        avatar). Pretrained on painted canonical renders from the start it was
#        worse on talking_d9 (session 62).
#   demo (steps 2-3 of builtin, with the general model already in OUT_DIR, ~30 min).
# Usage: deploy/make_default_models.sh [OUT_DIR] [builtin|ict|demo|all]   (default: models/ all)
#   WORK=DIR  keep the intermediate files (dataset, checkpoints, eval videos) there
#   ICT=DIR  the ICT-FaceKit folder (default ../shared/data/head-models/ict-facekit)
#   ICT_STAGE1=G.hcavatar  continue this first-stage ICT-FaceKit general model instead of pretraining one
# Shorter runs for a try: GENERAL_ITERATIONS=500 SUBJECT_ITERATIONS=200 ICT_ITERATIONS=300 ICT_CONTINUE_ITERATIONS=100 \
#   deploy/make_default_models.sh /tmp/m
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=${HEADCAST_BIN:-$here/build/bin}
out=${1:-$here/models}
which=${2:-all}
general_iterations=${GENERAL_ITERATIONS:-6000}
subject_iterations=${SUBJECT_ITERATIONS:-3000}
demo_train=${DEMO_TRAIN_FRAMES:-900}
ict_iterations=${ICT_ITERATIONS:-4000}
ict_continue_iterations=${ICT_CONTINUE_ITERATIONS:-1500}
ict=${ICT:-$here/../shared/data/head-models/ict-facekit}
case $which in builtin | ict | all | demo) ;; *) echo "make_default_models: builtin, ict, demo or all, not $which" >&2; exit 2 ;; esac
if [ -n "${WORK:-}" ]; then
  work=$WORK  # kept: the intermediate dataset, checkpoints and eval videos
  mkdir -p "$work"
else
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
fi
mkdir -p "$out"

if [ "$which" = ict ] || [ "$which" = all ]; then
  [ -d "$ict/FaceXModel" ] || { echo "make_default_models: no ICT-FaceKit folder at $ict (set ICT=DIR)" >&2; exit 2; }
  echo "== ICT-FaceKit, compact (int16 bases, 5 µm a step), painted"
  "$bin/headcast-headmodel" convert ict --folder "$ict" --basis-step 5e-6 --out "$out/ict_facekit.npz" > /dev/null
  cp "$ict/LICENSE" "$out/ict_facekit.LICENSE"
  mkdir -p "$out/ict_general/stage1"
  stage1=$work/ict_general_stage1.hcavatar
  if [ -n "${ICT_STAGE1:-}" ]; then
    echo "== general model for ICT-FaceKit, stage 1: $ICT_STAGE1 as given"
    cp "$ICT_STAGE1" "$stage1"  # OUT's own may be it, and is overwritten below
  else
    echo "== general model for ICT-FaceKit, stage 1 (unpainted renders, 128 px, $ict_iterations steps, 2 processes)"
    "$bin/headcast-headmodel" convert ict --folder "$ict" --basis-step 5e-6 --no-paint-parts \
      --out "$work/ict_unpainted.npz" > /dev/null
    "$bin/headcast-train" pretrain --head-model "$work/ict_unpainted.npz" --resolution 128 \
      --iterations "$ict_iterations" --processes 2 --eval 40 --eval-every 500 \
      --log-csv "$out/ict_general/stage1/loss.csv" --eval-csv "$out/ict_general/stage1/eval.csv" \
      --plots "$out/ict_general/stage1" --preview "$out/ict_general/stage1/preview.png" \
      --json "$out/ict_general/stage1/report.json" --checkpoint-dir "$work/ckpt_ict" --out "$stage1" > /dev/null
  fi
  echo "== stage 2: continued on painted renders, canonical samples, covered parts apart ($ict_continue_iterations steps)"
  "$bin/headcast-train" pretrain --head-model "$out/ict_facekit.npz" --init "$stage1" --resolution 128 \
    --iterations "$ict_continue_iterations" --processes 2 --eval 40 --eval-every 500 --canonical-samples \
    --covered-apart --log-csv "$out/ict_general/loss.csv" --eval-csv "$out/ict_general/eval.csv" \
    --plots "$out/ict_general" --preview "$out/ict_general/preview.png" --json "$out/ict_general/report.json" \
    --checkpoint-dir "$work/ckpt_ict2" --out "$out/ict_general.hcavatar" > /dev/null
  /usr/bin/python3 "$here/bench/strip_machine_paths.py" --root "$here" "$out/ict_general"
  [ "$which" = ict ] && { du -sh "$out"; exit 0; }
fi
mkdir -p "$out/general" "$out/demo"

if [ "$which" != demo ]; then
  echo "== 1. general model (built-in head, 128 px, $general_iterations steps)"
  "$bin/headcast-train" pretrain --head-model builtin --resolution 128 --iterations "$general_iterations" --batch 4 \
    --neck-deg 30 --eval 40 --eval-every 500 --log-csv "$out/general/loss.csv" --eval-csv "$out/general/eval.csv" \
    --plots "$out/general" --preview "$out/general/preview.png" --json "$out/general/report.json" \
    --checkpoint-dir "$work/ckpt_general" --out "$out/builtin_general.hcavatar" > /dev/null
fi

echo "== 2. demo subject: $demo_train + 150 rendered RGB-D frames; the first $demo_train train the avatar, the last 150 are the demo input"
subject_shape=(0=0.8 3=-0.5 5=0.6)
"$bin/headcast-headmodel" render-rgbd builtin --out "$work/render" --frames $((demo_train + 150)) --size 640 \
  $(printf -- '--shape %s ' "${subject_shape[@]}") > /dev/null
# The training part as an RGB-D folder of its own: the first frames' pairs.
mkdir -p "$work/train"
ln -sfn ../render/rgb "$work/train/rgb"
ln -sfn ../render/depth "$work/train/depth"
head -n $((demo_train + 1)) "$work/render/associations.txt" > "$work/train/associations.txt"
# The demo part as a colour video too (an RGB-only try: deploy/demo.sh --input models/demo/demo_sequence.mp4).
ffmpeg -loglevel error -y -framerate 30 -start_number "$demo_train" -i "$work/render/rgb/%05d.png" \
  -c:v libx264 -crf 18 -pix_fmt yuv420p "$out/demo/demo_sequence.mp4"
cp "$work/render/truth.json" "$out/demo/render_truth.json"
/usr/bin/python3 - "$out/demo/subject.json" "$demo_train" "${subject_shape[@]}" <<'PY'
import json, sys
path, first, shape = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
json.dump({"what": "the demo's input: headcast-headmodel render-rgbd builtin --first-frame F --frames N --size S "
                   "--shape ... (the avatar was made from the frames before F)",
           "first_frame": first, "frames": 150, "size": 640, "shape": shape}, open(path, "w"), indent=2)
PY

echo "== 3. the demo avatar: headcast-train create on the RGB-D frames (the renders' camera, $subject_iterations steps)"
# Run inside the work folder with relative paths, so the avatar's manifest names no path of this machine.
intrinsics=$(/usr/bin/python3 -c "import json; c = json.load(open('$work/render/truth.json'))['camera']; print(f\"{c['fx']},{c['fy']},{c['cx']},{c['cy']}\")")
cp "$out/builtin_general.hcavatar" "$work/general.hcavatar"
(cd "$work" && "$bin/headcast-train" create --input train --out demo_avatar.hcavatar --work create \
  --head-model builtin --general general.hcavatar --iterations "$subject_iterations" --test-frames 60 \
  --intrinsics "$intrinsics" --preview none > create.json)
cp "$work/demo_avatar.hcavatar" "$out/demo_avatar.hcavatar"
cp "$work/create.json" "$out/demo/create.json"
for f in dataset/dataset.json dataset/track_report.json loss.csv eval.csv plots/losses.png plots/psnr.png \
  preview.png eval/eval.json; do
  if [ -f "$work/create/$f" ]; then cp "$work/create/$f" "$out/demo/$(basename "$f")"; fi
done
cp "$work/create/fine_tune.json" "$out/demo/report.json"

# Shipped reports name no path of this machine.
/usr/bin/python3 "$here/bench/strip_machine_paths.py" --root "$here" "$out/demo" "$out/general"
du -sh "$out"
echo "wrote $out/builtin_general.hcavatar and $out/demo_avatar.hcavatar (reports beside them)"
