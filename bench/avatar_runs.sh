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
