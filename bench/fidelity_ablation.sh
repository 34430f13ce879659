#!/usr/bin/env bash
# Fidelity levers side by side: one prepared dataset, one general model, the
# same fine-tune steps and seed for every variant; each avatar evaluated on the
# held-out frames through the receiver's render path.
#   bench/fidelity_ablation.sh OUT [--general G.hcavatar] [--iterations N] [--video V] [--ict DIR]
#       [--dataset DS] [--variant NAME=FLAGS]... [--reuse]
# Without --variant: "thesis" (no surface texture, head-frame CNeRF samples,
# no matte: the thesis's avatar) and "default" (the default subject avatar).
# FLAGS are extra `headcast-train subject` flags, e.g. --variant
# 'surface16=--surface-features 16'. With --dataset, a prepared dataset (256²
# crops) is used instead of preparing the video.
# --reuse: variants whose avatar is already in OUT are evaluated again, not retrained.
# Writes OUT/ablation.{json,md} and prints the table.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/script_start.sh"
iterations=2000 name=fidelity_ablation dataset="" variants=() person=() reuse=0
while [ $# -gt 0 ]; do
  case $1 in
    --dataset) dataset=$2; shift 2 ;;
    --variant) variants+=("$2"); shift 2 ;;
    --reuse) reuse=1; shift ;;
    *) [ $# -ge 2 ] || { echo "$name: unknown option or one without its value: $1" >&2; exit 2; }
       person+=("$1" "$2"); shift 2 ;;
  esac
done
source "$root/bench/person_args.sh"
parse_person_args "${person[@]}"
[ ${#variants[@]} -gt 0 ] || variants=("thesis=--surface-features 0 --no-canonical-samples --matte none" "default=")
mkdir -p "$out"
out=$(cd "$out" && pwd)
source "$root/bench/avatar_runs.sh"
ict_and_general
if [ -z "$dataset" ]; then
  dataset=$out/ds
  [ -f "$dataset/dataset.json" ] || { step "prep"; prep_clip prep.log "$video" "$dataset"; }
fi
names=()
for variant in "${variants[@]}"; do
  vname=${variant%%=*} flags=${variant#*=}
  names+=("$vname")
  if [ $reuse = 0 ] || [ ! -f "$out/avatar_$vname.hcavatar" ]; then
    step "$vname: fine-tune ($iterations steps) $flags"
    # shellcheck disable=SC2086  # the variant's flags are words
    fine_tune_clip "subject_$vname.log" "$general" "$dataset" "$out/avatar_$vname.hcavatar" "$iterations" \
      --json "$out/subject_$vname.json" $flags
  fi
  step "$vname: eval"
  run "eval_$vname.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$vname.hcavatar" \
    --data "$dataset" --out "$out/eval_$vname" --orbit-frames 0
  printf '%s\n' "$flags" > "$out/flags_$vname.txt"
done

"$python" - "$out" "$command" "$iterations" "${names[@]}" <<'EOF'
import csv, json, os, sys
out, command, iterations, names = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
rows = []
for n in names:
    e = json.load(open(os.path.join(out, f"eval_{n}", "eval.json")))["eval"]
    s = json.load(open(os.path.join(out, f"subject_{n}.json")))
    psnr = sorted(float(r["psnr"]) for r in csv.DictReader(open(os.path.join(out, f"eval_{n}", "per_frame.csv"))))
    worst = psnr[:max(1, len(psnr) // 20)]
    fid = json.load(open(os.path.join(out, f"eval_{n}", "eval.json"))).get("expression_fidelity")
    fid = fid["result"] if isinstance(fid, dict) else {}
    rows.append({"variant": n, "flags": open(os.path.join(out, f"flags_{n}.txt")).read().strip(),
                 "test_psnr_db": e["psnr_db"], "test_ssim": e["ssim"],
                 "landmark_error_iod": fid.get("error_iod"), "blink_correlation": (fid.get("blink") or {}).get("correlation"),
                 "gaze_correlation_x": (fid.get("gaze") or {}).get("correlation_x"),
                 "gaze_correlation_y": (fid.get("gaze") or {}).get("correlation_y"),
                 "worst_5pct_psnr_db": sum(worst) / len(worst),
                 "fine_tune_s": s["fit"]["seconds"], "frames": len(psnr)})
result = {"command": command, "iterations": iterations, "rows": rows}
json.dump(result, open(os.path.join(out, "ablation.json"), "w"), indent=2)
L = [f"Made by `{command}`: {iterations} fine-tune steps at 256² per variant, same dataset, general model and seed.", "",
     "| variant | flags | test PSNR (dB) | test SSIM | worst 5 % PSNR (dB) | landmarks eyes / mouth / all (IOD) | blink corr. | gaze corr. x / y | fine-tune (s) |",
     "|---|---|---|---|---|---|---|---|---|"]
for x in rows:
    le = x["landmark_error_iod"] or {}
    marks = " / ".join(f"{le[k]:.4f}" for k in ("eyes", "mouth", "all")) if le else "–"
    blink = "–" if x["blink_correlation"] is None else f"{x['blink_correlation']:.2f}"
    gaze = " / ".join("–" if x[k] is None else f"{x[k]:.2f}" for k in ("gaze_correlation_x", "gaze_correlation_y"))
    L.append(f"| {x['variant']} | `{x['flags'] or '(defaults)'}` | {x['test_psnr_db']:.3f} | {x['test_ssim']:.4f} | "
             f"{x['worst_5pct_psnr_db']:.3f} | {marks} | {blink} | {gaze} | {x['fine_tune_s']:.0f} |")
open(os.path.join(out, "ablation.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
EOF
