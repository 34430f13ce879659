# Sourced by the scripts that build avatars of the shared clips
# (fidelity_ablation.sh, four_clips.sh): logging, running a step into a log,
# and the ICT-FaceKit model and general model they start from.
# Needs: out (the work folder), name (the script's name), bin, ict, general ("" to make one).
step() { echo "== $(date +%H:%M:%S) $*" >&2; }
run() {  # run LOG COMMAND...: the command's output goes to OUT/LOG; a failure stops the script
  local log=$1; shift
  "$@" > "$out/$log" 2>&1 || { echo "$name: failed, see $out/$log" >&2; exit 1; }
}
# Sets model (OUT/ict.npz, converted unless present) and general (made unless given or present).
ict_and_general() {
  model=$out/ict.npz
  [ -f "$model" ] || { step "ICT-FaceKit -> npz"; run convert.log "$bin/headcast-headmodel" convert ict \
    --folder "$ict" --out "$model"; }
  if [ -z "$general" ]; then
    general=$out/general128.hcavatar
    [ -f "$general" ] || { step "general model (128², 4000 steps)"; run pretrain.log "$bin/headcast-train" pretrain \
      --head-model "$model" --resolution 128 --iterations 4000 --processes 2 --out "$general"; }
  fi
}
# The four-clip table's prep and fine-tune, in one place, so that every script
# that runs "the table's settings" runs the same commands (needs model).
prep_clip() {  # prep_clip LOG VIDEO DS [PREP FLAGS...]: 256² crops, the last 150 frames held out
  local log=$1 video=$2 ds=$3; shift 3
  run "$log" "$bin/headcast-train" prep --input "$video" --head-model "$model" --out "$ds" --resolutions 256 \
    --test-frames 150 "$@"
}
fine_tune_clip() {  # fine_tune_clip LOG GENERAL DS AVATAR STEPS [SUBJECT FLAGS...]: at 256², 2 processes
  local log=$1 from=$2 ds=$3 avatar=$4 steps=$5; shift 5
  run "$log" "$bin/headcast-train" subject --head-model "$model" --general "$from" --data "$ds" --resolution 256 \
    --processes 2 --iterations "$steps" --z-augmentation "${z_augmentation:-0}" --out "$avatar" "$@"
}
