#!/usr/bin/env bash
# The matte's scale (AvatarConfig::matte_scale) swept on trained avatars: each
# avatar scored on its dataset's held-out frames at every scale through the
# receiver's render path (`headcast-train eval --matte-scale S`), the networks
# and frames the same, so that only the outline's softness differs. With
# --validation N the held-out frames are split: the first N (frames just
# after the training frames, to choose a scale on) apart from the rest (to
# score it on), each with its own mean PSNR and SSIM.
#   bench/matte_scale.sh OUT --head-model M.npz [--scales "0.4 0.5 0.6 0.75 1"] [--validation N]
#       NAME=AVATAR.hcavatar:DATASET ...
# Writes OUT/matte_scale.{json,md} and prints the table; the evaluations stay in OUT.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/script_start.sh"
name=matte_scale scales="0.4 0.5 0.6 0.75 1" validation=0 model="" runs=()
while [ $# -gt 0 ]; do
  case $1 in
    --head-model) model=$2; shift 2 ;;
    --scales) scales=$2; shift 2 ;;
    --validation) validation=$2; shift 2 ;;
    *=*:*) runs+=("$1"); shift ;;
    *) echo "$name: unknown argument $1 (NAME=AVATAR:DATASET expected)" >&2; exit 2 ;;
  esac
done
[ -n "$model" ] || { echo "$name: --head-model is required" >&2; exit 2; }
[ ${#runs[@]} -gt 0 ] || { echo "$name: no NAME=AVATAR:DATASET given" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
# The call as the results record it: files by their names, not their machine paths.
command="bench/matte_scale.sh OUT --head-model $(basename "$model") --scales \"$scales\" --validation $validation"
tags=""
for r in "${runs[@]}"; do
  tag=${r%%=*} rest=${r#*=}
  avatar=${rest%%:*} dataset=${rest#*:}
  command+=" $tag=$(basename "$avatar"):$(basename "$dataset")"
  tags+="$tag "
  for s in $scales; do
    echo "== $(date +%H:%M:%S) $tag: scale $s" >&2
    "$bin/headcast-train" eval --head-model "$model" --avatar "$avatar" --data "$dataset" \
      --out "$out/eval_${tag}_$s" --orbit-frames 0 --no-landmarks --matte-scale "$s" > "$out/eval_${tag}_$s.log" 2>&1 ||
      { echo "$name: eval failed, see $out/eval_${tag}_$s.log" >&2; exit 1; }
  done
done
"$python" - "$out" "$validation" "$command" "$scales" $tags <<'PY'
import csv, json, sys
out, validation, command, scales, tags = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4].split(), sys.argv[5:]
rows = []
for tag in tags:
    for s in scales:
        with open(f"{out}/eval_{tag}_{s}/per_frame.csv") as f:
            frames = list(csv.DictReader(f))
        psnr = [float(r["psnr"]) for r in frames]
        ssim = [float(r["ssim"]) for r in frames]
        if validation >= len(frames):
            sys.exit(f"matte_scale: {tag} has {len(frames)} held-out frames, --validation {validation} leaves none")
        mean = lambda v: sum(v) / len(v)
        row = {"avatar": tag, "scale": float(s), "frames": len(frames)}
        if validation:
            row.update(validation_psnr=mean(psnr[:validation]), validation_ssim=mean(ssim[:validation]),
                       rest_psnr=mean(psnr[validation:]), rest_ssim=mean(ssim[validation:]))
        row.update(psnr=mean(psnr), ssim=mean(ssim))
        rows.append(row)
json.dump({"command": command, "validation_frames": validation, "rows": rows}, open(f"{out}/matte_scale.json", "w"),
          indent=1)
head = "| avatar | scale | held-out PSNR (dB) | SSIM |"
if validation:
    head += f" first {validation} PSNR / SSIM | the rest PSNR / SSIM |"
lines = [f"`{command}`", "", head, "|" + "---|" * (head.count("|") - 1)]
for r in rows:
    line = f"| {r['avatar']} | {r['scale']:g} | {r['psnr']:.3f} | {r['ssim']:.4f} |"
    if validation:
        line += (f" {r['validation_psnr']:.3f} / {r['validation_ssim']:.4f} |"
                 f" {r['rest_psnr']:.3f} / {r['rest_ssim']:.4f} |")
    lines.append(line)
open(f"{out}/matte_scale.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
