#!/usr/bin/env bash
# The avatars of a four-clip run driven as a call drives them. Each clip is
# tracked again by the sender's rule (headcast-track: the avatar's identity,
# its training camera, the sender's landmark filter), once by landmarks alone
# (`headcast-sender --no-photometric-anchor`) and once held to the photometric
# anchor the avatar carries (the sender's default), and each track is
# evaluated on the clip's held-out frames against the same crops and masks as
# the run's own row, which prep's parameters drive (evaluated again here, so
# that every row has the same figures, the frame-to-frame ones included).
#   bench/live_drive.sh FOUR_CLIPS_OUT [--clips "d9 d10 ..."] [--drives "landmarks anchor"]
#                       [--landmark-filter causal|off] [--landmark-filter-hz HZ] [--landmark-filter-beta B]
# --landmark-filter: the sender's One-Euro filter (causal) or none, as prep
# takes them (off, the sender's default); --landmark-filter-hz/-beta: the
# filter's settings (headcast-track's defaults otherwise; they name the run).
# FOUR_CLIPS_OUT: the folder of `bench/four_clips.sh OUT` (its avatars must
# carry an anchor: prepared with one, by a build that records it). Writes
# FOUR_CLIPS_OUT/live_drive_TAG.{json,md} and prints the table.
set -euo pipefail
out_name=FOUR_CLIPS_OUT
source "$(dirname "${BASH_SOURCE[0]}")/script_start.sh"
name=live_drive clips="d9 d10 d14 d3" drives="landmarks anchor" filter=off hz="" beta=""
while [ $# -gt 0 ]; do
  case $1 in
    --clips) clips=$2; shift 2 ;;
    --drives) drives=$2; shift 2 ;;
    --landmark-filter) filter=$2; shift 2 ;;
    --landmark-filter-hz) hz=$2; shift 2 ;;
    --landmark-filter-beta) beta=$2; shift 2 ;;
    *) echo "$name: unknown option $1" >&2; exit 2 ;;
  esac
done
case $filter in causal | off) ;; *) echo "$name: --landmark-filter is causal or off, not $filter" >&2; exit 2 ;; esac
for d in $drives; do
  case $d in landmarks | anchor) ;; *) echo "$name: --drives takes landmarks and anchor, not $d" >&2; exit 2 ;; esac
done
filter_flags=(--landmark-filter "$filter") tag=$filter
if [ -n "$hz$beta" ]; then
  [ "$filter" = causal ] || { echo "$name: --landmark-filter-hz/-beta need --landmark-filter causal" >&2; exit 2; }
  [ -n "$hz" ] && filter_flags+=(--landmark-filter-hz "$hz") && tag+="_hz$hz"
  [ -n "$beta" ] && filter_flags+=(--landmark-filter-beta "$beta") && tag+="_beta$beta"
fi
out=$(cd "$out" && pwd)
source "$root/bench/avatar_runs.sh"
model=$out/ict.npz
[ -f "$model" ] || { echo "$name: no $model (not a four_clips.sh folder?)" >&2; exit 2; }
for clip in $clips; do
  ds=$out/ds_$clip avatar=$out/avatar_$clip.hcavatar
  [ -f "$avatar" ] && [ -f "$ds/dataset.json" ] || { echo "$name: no avatar or dataset of $clip in $out" >&2; exit 2; }
  camera=$("$python" -c "import json; print(','.join(map(str, json.load(open('$ds/dataset.json'))['crop']['source_camera'])))")
  if ! "$python" -c "import json, sys; sys.exit(0 if 'temporal' in json.load(open('$out/live_eval_prep_$clip/eval.json')) else 1)" 2> /dev/null; then
    step "$clip: eval (prep's parameters)"
    run "live_eval_prep_$clip.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$avatar" --data "$ds" \
      --out "$out/live_eval_prep_$clip" --orbit-frames 0
  fi
  for drive in $drives; do
    flag=(); [ $drive = anchor ] && flag=(--avatar-anchor)
    step "$clip: tracked as the sender does ($drive)"
    run "live_track_${tag}_${drive}_$clip.log" "$bin/headcast-track" --input "$data/video/talking_$clip.mp4" \
      --head-model "$model" --identity-from "$avatar" --intrinsics "$camera" "${filter_flags[@]}" "${flag[@]}" \
      --out "$out/live_${tag}_${drive}_$clip.hcrec" --json "$out/live_track_${tag}_${drive}_$clip.json"
    # The dataset's crops and masks, driven by the live track (the same frames, in order).
    d=$out/live_ds_${tag}_${drive}_$clip
    rm -rf "$d" && mkdir -p "$d"
    ln -s "$ds/256" "$d/256"
    cp "$ds/dataset.json" "$d/"
    cp "$out/live_${tag}_${drive}_$clip.hcrec" "$d/params.hcrec"
    run "live_export_${tag}_${drive}_$clip.log" "$bin/headcast-rec" export "$d/params.hcrec" --out "$d/params.npz"
    "$python" - "$d" <<'EOF' || { echo "$name: $clip ($drive): the live track fitted other frames than prep" >&2; exit 1; }
import json, sys
import numpy as np
d = sys.argv[1]
want = json.load(open(f"{d}/dataset.json"))["frame_numbers"]
got = np.load(f"{d}/params.npz")["sequence"].tolist()
sys.exit(0 if got == want else 1)
EOF
    step "$clip: eval ($drive)"
    run "live_eval_${tag}_${drive}_$clip.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$avatar" \
      --data "$d" --out "$out/live_eval_${tag}_${drive}_$clip" --orbit-frames 0
  done
done

"$python" - "$out" "$command" "$tag" "$filter" "$drives" $clips <<'EOF'
import csv, json, os, sys
out, command, tag, filt, drives, clips = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5].split(), sys.argv[6:]
def row(folder):
    ev = json.load(open(os.path.join(out, folder, "eval.json")))
    psnr = sorted(float(r["psnr"]) for r in csv.DictReader(open(os.path.join(out, folder, "per_frame.csv"))))
    worst = psnr[:max(1, len(psnr) // 20)]
    fid = ev["expression_fidelity"]
    fid = fid["result"] if isinstance(fid, dict) else {}
    t = ev["temporal"]
    return {"psnr_db": ev["eval"]["psnr_db"], "ssim": ev["eval"]["ssim"], "worst_5pct_psnr_db": sum(worst) / len(worst),
            "landmark_error_iod": (fid.get("error_iod") or {}).get("all"),
            "blink_correlation": (fid.get("blink") or {}).get("correlation"),
            "change_psnr_db": t["change_psnr_db"], "motion_ratio": t["motion_ratio"]}
rows = []
for c in clips:
    r = {"clip": f"talking_{c}", "prep": row(f"live_eval_prep_{c}")}
    for drive in drives:
        r[drive] = row(f"live_eval_{tag}_{drive}_{c}")
        track = json.load(open(os.path.join(out, f"live_track_{tag}_{drive}_{c}.json")))
        r[drive]["ms_per_frame_median"] = track["ms_per_frame_median"]
        if drive == "anchor":
            a = track["photometric_anchor"]
            r[drive]["frames_anchored"], r[drive]["frames_fitted"] = a["frames_anchored"], track["fitted_frames"]
            r[drive]["anchor_ms_median"] = a["anchor_ms_median"]
    rows.append(r)
json.dump({"command": command, "landmark_filter": tag, "rows": rows},
          open(os.path.join(out, f"live_drive_{tag}.json"), "w"), indent=2)
f = lambda v, fmt: "–" if v is None else format(v, fmt)
L = [f"Made by `{command}`: each avatar on its clip's 150 held-out frames, the same crops and masks, driven by prep's "
     "parameters (the four-clip row), by the sender's rule with landmarks alone, and by the sender's rule held to the "
     "avatar's photometric anchor; the sender's landmarks: " + {"causal": "One-Euro filtered", "off": "as found "
     "(unfiltered, as prep takes them)"}[filt] + f" ({tag}). Landmark error: dlib's 68 points on avatar against true "
     "frames, over the eye distance. Change PSNR: the avatar's frame-to-frame change against the truth's (dB; higher: "
     "steadier where the person is); motion: the ratio of their rms changes (above 1: the avatar moves more than the "
     "person). ms: headcast-track's tracking per frame (landmarks and fit, one core).", "",
     "| clip | drive | PSNR (dB) | SSIM | worst 5 % PSNR | landmark error (IOD) | blink corr. | change PSNR (dB) | "
     "motion | frames anchored | ms per frame (anchor) |",
     "|---|---|---|---|---|---|---|---|---|---|---|"]
labels = {"prep": "prep's parameters", "landmarks": "live, landmarks", "anchor": "live, anchored"}
for r in rows:
    for drive in ["prep"] + drives:
        x = r[drive]
        anchored = f"{x['frames_anchored']} / {x['frames_fitted']}" if "frames_anchored" in x else "–"
        ms = "–" if "ms_per_frame_median" not in x else f"{x['ms_per_frame_median']:.1f}" + (
            f" ({x['anchor_ms_median']:.1f})" if "anchor_ms_median" in x else "")
        L.append(f"| {r['clip']} | {labels[drive]} | {x['psnr_db']:.3f} | {x['ssim']:.4f} | {x['worst_5pct_psnr_db']:.2f} | "
                 f"{f(x['landmark_error_iod'], '.4f')} | {f(x['blink_correlation'], '.2f')} | "
                 f"{f(x['change_psnr_db'], '.2f')} | {f(x['motion_ratio'], '.3f')} | {anchored} | {ms} |")
open(os.path.join(out, f"live_drive_{tag}.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
EOF
