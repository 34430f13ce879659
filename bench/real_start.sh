#!/usr/bin/env bash
# A start that has seen real faces (issue #22): for each clip, the general model
# continued on the OTHER clips' training frames (`headcast-train pretrain --init
# G --real ...`: that person is left out), then the clip's avatar fine-tuned
# from it exactly as bench/four_clips.sh fine-tunes from G, and evaluated on its
# held-out frames. Beside it in the table: the four_clips run's avatar of the
# same dataset (from G), and with --control N the clip fine-tuned from G for N
# steps (pretrain + fine-tune steps: the same number of steps on real frames).
#   bench/real_start.sh OUT --datasets DIR [--general G.hcavatar] [--clips "d9 d10 d14 d3"]
#       [--pretrain-iterations N (3000)] [--iterations N (3000)] [--control N (0: none)]
#       [--pretrain-flags "FLAGS"]   (default: --region-weight 4 --weight-average 0.997 --canonical-samples)
# DIR is a bench/four_clips.sh OUT: its ict.npz, ds_CLIP and, when there, eval_CLIP.
# Writes OUT/real_start.{json,md}; the general models it makes (from ../shared/data) stay in OUT, never shipped.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${HEADCAST_PYTHON:-/usr/bin/python3}
bin=${HEADCAST_BIN:-$root/build/bin}
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
command="bench/real_start.sh OUT $*"  # no machine paths in what is written
name=real_start datasets="" general=$root/models/ict_general.hcavatar clips="d9 d10 d14 d3"
pretrain_iterations=3000 iterations=3000 control=0
pretrain_flags="--region-weight 4 --weight-average 0.997 --canonical-samples"
while [ $# -gt 0 ]; do
  case $1 in
    --datasets) datasets=$2; shift 2 ;;
    --general) general=$2; shift 2 ;;
    --clips) clips=$2; shift 2 ;;
    --pretrain-iterations) pretrain_iterations=$2; shift 2 ;;
    --iterations) iterations=$2; shift 2 ;;
    --control) control=$2; shift 2 ;;
    --pretrain-flags) pretrain_flags=$2; shift 2 ;;
    *) echo "$name: unknown option $1" >&2; exit 2 ;;
  esac
done
command=${command//"$datasets"/DIR}
[ -n "$datasets" ] || { echo "$name: --datasets DIR (a bench/four_clips.sh OUT) is required" >&2; exit 2; }
model=$datasets/ict.npz
[ -f "$model" ] || { echo "$name: no $model: is $datasets a bench/four_clips.sh OUT?" >&2; exit 2; }
[ -f "$general" ] || { echo "$name: no general model $general" >&2; exit 2; }
all="d9 d10 d14 d3"
for c in $all; do
  [ -d "$datasets/ds_$c" ] || { echo "$name: no prepared dataset $datasets/ds_$c" >&2; exit 2; }
done
mkdir -p "$out"
out=$(cd "$out" && pwd)
source "$root/bench/avatar_runs.sh"
fine_tune() {  # fine_tune LABEL GENERAL STEPS: as bench/four_clips.sh fine-tunes, then eval
  local label=$1 from=$2 steps=$3
  step "$clip: fine-tune $label ($steps steps)"
  fine_tune_clip "subject_$label.log" "$from" "$datasets/ds_$clip" "$out/avatar_$label.hcavatar" "$steps" \
    --json "$out/subject_$label.json"
  step "$clip: eval $label"
  run "eval_$label.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$label.hcavatar" \
    --data "$datasets/ds_$clip" --out "$out/eval_$label" --orbit-frames 0
}
for clip in $clips; do
  others=()
  for c in $all; do [ "$c" = "$clip" ] || others+=(--real "$datasets/ds_$c"); done
  step "$clip: the general model continued on the other clips (${others[*]}), $pretrain_iterations steps"
  t0=$(date +%s.%N)
  # shellcheck disable=SC2086  # the extra flags are words
  run "pretrain_no_$clip.log" "$bin/headcast-train" pretrain --head-model "$model" --resolution 256 --init "$general" \
    "${others[@]}" --iterations "$pretrain_iterations" --processes 2 --mix-m 0 --mix-n "$pretrain_iterations" \
    --p-max 0.25 --p-min 0.1 $pretrain_flags --json "$out/pretrain_no_$clip.json" --out "$out/general_no_$clip.hcavatar"
  "$python" -c "import json; json.dump({'pretrain_s': $(date +%s.%N) - $t0}, open('$out/time_no_$clip.json', 'w'))"
  fine_tune "$clip" "$out/general_no_$clip.hcavatar" "$iterations"
  if [ "$control" -gt 0 ]; then fine_tune "control_$clip" "$general" "$control"; fi
done

"$python" - "$out" "$datasets" "$command" "$control" $clips <<'EOF'
import json, os, sys
out, datasets, command, control, clips = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5:]
def figures(d):
    p = os.path.join(d, "eval.json")
    if not os.path.exists(p):
        return None
    e = json.load(open(p))
    fid = e["expression_fidelity"]
    fid = fid["result"] if isinstance(fid, dict) else {}
    return {"psnr_db": e["eval"]["psnr_db"], "ssim": e["eval"]["ssim"],
            "landmark_error_all": (fid.get("error_iod") or {}).get("all"),
            "blink_correlation": (fid.get("blink") or {}).get("correlation"),
            "gaze_correlation_x": (fid.get("gaze") or {}).get("correlation_x")}
rows = []
for c in clips:
    mix = json.load(open(os.path.join(out, f"pretrain_no_{c}.json")))["mix"]
    mix["datasets"] = ["DIR/" + os.path.basename(d) for d in mix["datasets"]]  # no machine paths in what is written
    rows.append({"clip": f"talking_{c}", "pretrain": mix,
                 "pretrain_s": json.load(open(os.path.join(out, f"time_no_{c}.json")))["pretrain_s"],
                 "from_general": figures(os.path.join(datasets, f"eval_{c}")),
                 "from_real_start": figures(os.path.join(out, f"eval_{c}")),
                 "control": figures(os.path.join(out, f"eval_control_{c}")) if control else None})
json.dump({"command": command, "control_steps": control, "rows": rows}, open(os.path.join(out, "real_start.json"), "w"),
          indent=2)
def cell(x):
    if not x:
        return "–"
    s = f"{x['psnr_db']:.3f} / {x['ssim']:.4f}"
    if x["landmark_error_all"] is not None:
        s += f" ({x['landmark_error_all']:.4f}, {x['blink_correlation']:.2f}, {x['gaze_correlation_x']:.2f})"
    return s
L = [f"Made by `{command}` on a bench/four_clips.sh run's datasets. Each cell: test PSNR (dB) / SSIM (landmark error "
     "all, blink corr., gaze corr. x). From G: that run's avatar; real start: fine-tuned from G continued on the other "
     "clips' training frames (the clip's person left out)" + (f"; control: from G, {control} steps" if control else "") + ".", "",
     "| clip | from G | real start | control | pretrain (min) |", "|---|---|---|---|---|"]
for r in rows:
    L.append(f"| {r['clip']} | {cell(r['from_general'])} | {cell(r['from_real_start'])} | {cell(r['control'])} | "
             f"{r['pretrain_s'] / 60:.1f} |")
open(os.path.join(out, "real_start.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
EOF
