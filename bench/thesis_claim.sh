#!/usr/bin/env bash
# The thesis's central claim, measured here (METHOD §6): fine-tuning a subject's
# avatar from the general model reaches a given test PSNR in fewer iterations
# than training the same networks from scratch. Same data, steps, batch, seed
# and schedule; the held-out PSNR every EVAL_EVERY steps, both curves in one plot.
# Usage: bench/thesis_claim.sh DATASET GENERAL.hcavatar OUT_DIR [HEAD_MODEL] [RESOLUTION] [ITERATIONS]
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin=${HEADCAST_BIN:-$here/build/bin}
data=$1 general=$2 out=$3 head_model=${4:-builtin} resolution=${5:-128} iterations=${6:-1000}
every=${EVAL_EVERY:-50}
mkdir -p "$out"
common=(subject --head-model "$head_model" --data "$data" --resolution "$resolution" --iterations "$iterations"
        --batch 4 --eval 30 --eval-every "$every" --seed 1)
"$bin/headcast-train" "${common[@]}" --general "$general" --eval-csv "$out/from_general.csv" \
  --json "$out/from_general.json" --out "$out/from_general.hcavatar" > /dev/null
"$bin/headcast-train" "${common[@]}" --from-scratch --eval-csv "$out/from_scratch.csv" \
  --json "$out/from_scratch.json" --out "$out/from_scratch.hcavatar" > /dev/null
"$bin/headcast-train" plot --series "$out/from_general.csv:psnr:from the general model" \
  --series "$out/from_scratch.csv:psnr:from scratch" --title "test PSNR, $(basename "$data"), ${resolution} px" \
  --y-label dB --out "$out/curves.png" > /dev/null
python3=${HEADCAST_PYTHON:-/usr/bin/python3}
"$python3" - "$out" <<'PY'
import csv, json, sys
out = sys.argv[1]
runs = {name: [(int(r["step"]), float(r["psnr"])) for r in csv.DictReader(open(f"{out}/{name}.csv"))]
        for name in ("from_general", "from_scratch")}
best_scratch = max(p for _, p in runs["from_scratch"])
def first_reaching(curve, level):
    return next((s for s, p in curve if p >= level), None)
levels = sorted({round(best_scratch - d, 1) for d in (3.0, 2.0, 1.0, 0.0)})
table = [{"psnr_db": l, "steps_from_general": first_reaching(runs["from_general"], l),
          "steps_from_scratch": first_reaching(runs["from_scratch"], l)} for l in levels]
result = {"final_psnr_db": {k: v[-1][1] for k, v in runs.items()}, "steps_to_reach": table,
          "plot": f"{out}/curves.png"}
json.dump(result, open(f"{out}/claim.json", "w"), indent=2)
print(json.dumps(result, indent=2))
PY
echo "reproduce: bench/thesis_claim.sh $*"
