#!/usr/bin/env bash
# A real person's avatar, timed step by step: a talking-head video with the
# ICT-FaceKit head model, the last 150 frames held out, test PSNR/SSIM at 128²
# and 256². Writes bench/results/real_person.{json,md}; the work (datasets,
# avatars, evaluation videos) stays in OUT.
#   bench/real_person.sh OUT [--general G.hcavatar] [--iterations N] [--video V] [--ict DIR]
# --general: an ICT-FaceKit general model at 128² (made once per head model,
#   so not part of one avatar's creation time); without it one is pretrained
#   first (4000 steps, --processes 2) and its time reported apart.
# --iterations: fine-tune steps at each resolution, 10000 by default (25.5 min of
#   avatar creation at 256² on 2 cores, 26.14 dB on talking_d9).
# The creation time of an avatar is prep (tracking included) + fine-tune.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=$root/build/bin
python=${HEADCAST_PYTHON:-/usr/bin/python3}
data=${HEADCAST_DATA:-$root/../shared/data}
command="bench/real_person.sh $*"
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
test_frames=150 iterations=10000 name=real_person
source "$root/bench/person_args.sh"
parse_person_args "$@"
mkdir -p "$out" "$root/bench/results"
out=$(cd "$out" && pwd)
step() { echo "== $*" >&2; }
declare -A seconds
timed() {  # timed NAME COMMAND...: runs it, logs to OUT/NAME.log, keeps its wall time
  local name=$1; shift
  local t0; t0=$(date +%s.%N)
  "$@" > "$out/$name.log" 2>&1 || { echo "real_person: $name failed, see $out/$name.log" >&2; exit 1; }
  seconds[$name]=$("$python" -c "print(round($(date +%s.%N) - $t0, 1))")
  step "$name: ${seconds[$name]} s"
}

step "ICT-FaceKit -> npz"
"$bin/headcast-headmodel" convert ict --folder "$ict" --out "$out/ict.npz" > /dev/null
model=$out/ict.npz
if [ -z "$general" ]; then
  step "pretrain the general model (128², synthetic renders)"
  general=$out/general128.hcavatar
  timed pretrain "$bin/headcast-train" pretrain --head-model "$model" --resolution 128 --iterations 4000 \
    --processes 2 --out "$general" --json "$out/pretrain.json"
fi
step "prep (tracking, identity, crops, masks)"
rm -rf "$out/ds"
timed prep "$bin/headcast-train" prep --input "$video" --head-model "$model" --out "$out/ds" \
  --resolutions 128,256 --test-frames $test_frames
for r in 128 256; do
  step "fine-tune at ${r}² ($iterations steps, 2 processes)"
  timed "subject_$r" "$bin/headcast-train" subject --head-model "$model" --general "$general" --data "$out/ds" \
    --resolution $r --processes 2 --iterations "$iterations" --z-augmentation 0 --eval-every 1000 --eval 30 \
    --out "$out/avatar_$r.hcavatar" --eval-csv "$out/subject_${r}_eval.csv" --json "$out/subject_$r.json"
  step "eval at ${r}²"
  "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$r.hcavatar" --data "$out/ds" \
    --out "$out/eval_$r" --orbit-frames 0 > "$out/eval_$r.log" 2>&1
done

"$python" - "$out" "$command" "$root/bench/results" "${seconds[prep]}" "${seconds[subject_128]}" \
  "${seconds[subject_256]}" "${seconds[pretrain]:-}" "$general" "$video" "$iterations" <<'EOF'
import json, os, sys
out, command, res, prep, s128, s256, pretrain, general, video, iterations = sys.argv[1:]
ds = json.load(open(os.path.join(out, "ds", "dataset.json")))
result = {"command": command, "video": os.path.basename(video), "head_model": "ICT-FaceKit",
          "general_model": os.path.basename(general),
          "general_model_seconds": float(pretrain) if pretrain else None,
          "frames": ds["frames_read"], "split": ds["split"], "tracking": ds["tracking"], "masks": ds["masks"],
          "prep_seconds": float(prep), "iterations": int(iterations), "resolutions": {}}
for r, s in (("128", s128), ("256", s256)):
    ev = json.load(open(os.path.join(out, f"eval_{r}", "eval.json")))["eval"]
    rep = json.load(open(os.path.join(out, f"subject_{r}.json")))
    result["resolutions"][r] = {"test_psnr_db": ev["psnr_db"], "test_ssim": ev["ssim"], "test_frames": ev["frames"],
                                "finetune_seconds": float(s), "samples_per_s": rep["fit"]["samples_per_s"],
                                "creation_minutes": (float(prep) + float(s)) / 60}
json.dump(result, open(os.path.join(res, "real_person.json"), "w"), indent=2)
L = [f"{result['video']} with ICT-FaceKit: {ds['split']['train']} training frames, the last {ds['split']['test']} "
     f"held out; {iterations} fine-tune steps from `{result['general_model']}` with 2 processes. Made by `{command}`.", "",
     "| resolution | test PSNR (dB) | test SSIM | prep (s) | fine-tune (s) | avatar creation (min) |", "|---|---|---|---|---|---|"]
for r, v in result["resolutions"].items():
    L.append(f"| {r}² | {v['test_psnr_db']:.3f} | {v['test_ssim']:.3f} | {prep} | {v['finetune_seconds']:.0f} | "
             f"{v['creation_minutes']:.1f} |")
if pretrain:
    L += ["", f"The general model took {float(pretrain):.0f} s (once per head model)."]
open(os.path.join(res, "real_person.md"), "w").write("\n".join(L) + "\n")
print(json.dumps(result, indent=2))
EOF
# Committed results name no path of this machine.
"$python" "$root/bench/strip_machine_paths.py" --root "$root" --data "$data" "$root/bench/results/real_person.json" \
  "$root/bench/results/real_person.md"
