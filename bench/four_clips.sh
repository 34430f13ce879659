#!/usr/bin/env bash
# The fidelity table of issue #22: every talking-head clip in the shared data,
# ICT-FaceKit, the last 150 frames held out, one avatar per clip at 256² with
# the default subject settings; per clip the test PSNR/SSIM, the worst 5 % of
# test frames, the landmark error by region and the blink correlation (dlib on
# avatar and true frames), the frames whose fit the tracker lost, and the
# avatar's creation time (prep + fine-tune), the frames whose brow or mouth
# landmarks the tracker disputed and repaired, and the PSNR/SSIM on 150 of the
# avatar's own training frames (what it fits against what it generalises to),
# and the test PSNR/SSIM with each frame's hair outline as a sender with
# --outline sends it (eval --outline-bins 12);
# then the receiver's frame rate on each clip's avatar at 256² (headcast-avatar
# render, synthetic motion: the avatar as trained, with the head model's
# expression coefficients) and on a random avatar of the default subject
# configuration at 256² and 512² (headcast-bench render, the builtin head).
#   bench/four_clips.sh OUT [--general G.hcavatar] [--iterations N (3000, as headcast-train create)] [--ict DIR]
#       [--clips "d9 d10 ..."]
#       [--z-augmentation P]        probability of the distance augmentation (0, as headcast-train create)
#       [--subject-flags "FLAGS"]   extra `headcast-train subject` flags (default: none)
#       [--prep-flags "FLAGS"]      extra `headcast-train prep` flags (default: none)
#       [--no-render]               skip the receiver's frame rate (ablations of the avatar only)
#       [--reuse]                   keep the datasets, avatars and evaluations OUT already has (the receiver and
#                                   the table only; a clip without them is made as usual)
# Writes OUT/four_clips.{json,md} and prints the table; the work stays in OUT.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/script_start.sh"
name=four_clips iterations=3000 z_augmentation=0 general="" ict=$data/head-models/ict-facekit clips="d9 d10 d14 d3" subject_flags="" prep_flags="" render=1 reuse=0
while [ $# -gt 0 ]; do
  case $1 in
    --general) general=$2; shift 2 ;;
    --iterations) iterations=$2; shift 2 ;;
    --z-augmentation) z_augmentation=$2; shift 2 ;;
    --ict) ict=$2; shift 2 ;;
    --clips) clips=$2; shift 2 ;;
    --subject-flags) subject_flags=$2; shift 2 ;;
    --prep-flags) prep_flags=$2; shift 2 ;;
    --no-render) render=0; shift ;;
    --reuse) reuse=1; shift ;;
    *) echo "$name: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -d "$ict" ] || { echo "four_clips: no ICT-FaceKit folder $ict" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
source "$root/bench/avatar_runs.sh"
ict_and_general
for clip in $clips; do
  video=$data/video/talking_$clip.mp4
  [ -f "$video" ] || { echo "four_clips: no video $video" >&2; exit 2; }
  if [ "$reuse" = 1 ] && [ -f "$out/avatar_$clip.hcavatar" ] && [ -f "$out/eval_$clip/eval.json" ] &&
    [ -f "$out/eval_train_$clip/eval.json" ] && [ -f "$out/time_$clip.json" ]; then
    step "$clip: reusing OUT's dataset, avatar and evaluations"
    continue
  fi
  t0=$(date +%s.%N)
  step "$clip: prep $prep_flags"
  rm -rf "$out/ds_$clip"
  # shellcheck disable=SC2086  # the extra flags are words
  prep_clip "prep_$clip.log" "$video" "$out/ds_$clip" $prep_flags
  t1=$(date +%s.%N)
  step "$clip: fine-tune ($iterations steps) $subject_flags"
  # shellcheck disable=SC2086  # the extra flags are words
  fine_tune_clip "subject_$clip.log" "$general" "$out/ds_$clip" "$out/avatar_$clip.hcavatar" "$iterations" \
    --json "$out/subject_$clip.json" $subject_flags
  t2=$(date +%s.%N)
  "$python" -c "import json; json.dump({'prep_s': $t1 - $t0, 'fine_tune_s': $t2 - $t1}, open('$out/time_$clip.json', 'w'))"
  step "$clip: eval"
  run "eval_$clip.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$clip.hcavatar" \
    --data "$out/ds_$clip" --out "$out/eval_$clip" --orbit-frames 0
  step "$clip: eval on training frames"
  run "eval_train_$clip.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$clip.hcavatar" \
    --data "$out/ds_$clip" --out "$out/eval_train_$clip" --split train --max-frames 150 --orbit-frames 0 --no-landmarks
done
for clip in $clips; do
  [ -f "$out/eval_outline_$clip/eval.json" ] && continue
  step "$clip: eval with each frame's hair outline, as a sender with --outline sends it"
  run "eval_outline_$clip.log" "$bin/headcast-train" eval --head-model "$model" --avatar "$out/avatar_$clip.hcavatar" \
    --data "$out/ds_$clip" --out "$out/eval_outline_$clip" --orbit-frames 0 --no-landmarks --outline-bins 12
done
for clip in $clips; do
  [ "$render" = 1 ] || break
  step "$clip: the receiver on its avatar"
  run "receiver_$clip.log" "$bin/headcast-avatar" render "$out/avatar_$clip.hcavatar" --head-model "$model" \
    --display none --pacing none --threads 2 --synthetic 150 --json "$out/receiver_$clip.json"
done
for r in 256 512; do
  [ "$render" = 1 ] || break
  step "render ${r}²"
  run "render_$r.log" "$bin/headcast-bench" render --resolution $r --repeats 100 --head-model "$model" \
    --json "$out/render_$r.json"
done

"$python" - "$out" "$command" "$iterations" $clips <<'EOF'
import csv, json, os, sys
out, command, iterations, clips = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
rows = []
for c in clips:
    ev = json.load(open(os.path.join(out, f"eval_{c}", "eval.json")))
    e = ev["eval"]
    fid = ev["expression_fidelity"]
    fid = fid["result"] if isinstance(fid, dict) else {}
    psnr = sorted(float(r["psnr"]) for r in csv.DictReader(open(os.path.join(out, f"eval_{c}", "per_frame.csv"))))
    worst = psnr[:max(1, len(psnr) // 20)]
    ds = json.load(open(os.path.join(out, f"ds_{c}", "dataset.json")))
    t = json.load(open(os.path.join(out, f"time_{c}.json")))
    track = json.load(open(os.path.join(out, f"ds_{c}", "track_report.json")))
    tr = json.load(open(os.path.join(out, f"eval_train_{c}", "eval.json")))["eval"]
    checks = track.get("landmark_checks") or {}
    rows.append({"clip": f"talking_{c}", "test_psnr_db": e["psnr_db"], "test_ssim": e["ssim"],
                 "worst_5pct_psnr_db": sum(worst) / len(worst), "test_frames": e["frames"],
                 "train_psnr_db": tr["psnr_db"], "train_ssim": tr["ssim"], "train_frames": tr["frames"],
                 "landmark_error_iod": fid.get("error_iod"), "landmarks_found": fid.get("found_in_both"),
                 "landmarks_against_fit": fid.get("fit"),
                 "blink_correlation": (fid.get("blink") or {}).get("correlation"),
                 "gaze_correlation_x": (fid.get("gaze") or {}).get("correlation_x"),
                 "gaze_correlation_y": (fid.get("gaze") or {}).get("correlation_y"),
                 "frames_read": ds.get("frames_read"), "frames_fitted": ds.get("frames_fitted"), "split": ds.get("split"),
                 "landmark_disputed_frames": checks.get("disputed_frames"),
                 "landmark_disputed": checks.get("disputed"), "landmark_repaired_frames": checks.get("repaired_frames"),
                 "prep_s": t["prep_s"], "fine_tune_s": t["fine_tune_s"],
                 "creation_min": (t["prep_s"] + t["fine_tune_s"]) / 60})
    outlined = os.path.join(out, f"eval_outline_{c}", "eval.json")
    if os.path.exists(outlined):
        e2 = json.load(open(outlined))["eval"]
        rows[-1]["with_outline"] = {"test_psnr_db": e2["psnr_db"], "test_ssim": e2["ssim"]}
    receiver = os.path.join(out, f"receiver_{c}.json")
    if os.path.exists(receiver):
        j = json.load(open(receiver))
        rows[-1]["receiver_256"] = {"fps": j["fps"], "ms_median": j["render_ms_median"], "ms_p95": j["render_ms_p95"],
                                    "threads": 2}
render = {}
for r in ("256", "512"):
    if not os.path.exists(os.path.join(out, f"render_{r}.json")):
        continue
    j = json.load(open(os.path.join(out, f"render_{r}.json")))
    # Frames that carry a skin colour, as a default sender's do (the receiver then matches it).
    render[r] = {k: j["subject_default_skin_colour"][k] for k in ("fps_median", "ms_median", "ms_p95")}
    render[r]["threads"] = j["threads"]
    render[r]["head_model"] = j.get("head_model", "builtin")
    render[r]["expressions"] = j.get("head_model_expressions")
result = {"command": command, "iterations": iterations, "rows": rows, "render_subject_default": render}
json.dump(result, open(os.path.join(out, "four_clips.json"), "w"), indent=2)
def f(v, fmt):
    return "–" if v is None else format(v, fmt)
L = [f"Made by `{command}`: ICT-FaceKit, the last 150 frames held out, {iterations} fine-tune steps at 256² "
     "(default subject settings, 2 processes). Landmark error: dlib's 68 points on avatar against true test "
     "frames, over the true eye distance. Training frames: 150 of the avatar's own training frames, spread evenly over them, "
     "through the same render path (no per-frame offsets). With the sender's outline: each held-out frame carries the top of its "
     "own mask's outline, as a sender with `--outline` measures it (`eval --outline-bins 12`).", "",
     "| clip | fitted / read | landmarks disputed / repaired (frames) | test PSNR (dB) | test SSIM | worst 5 % PSNR | with the sender's outline: PSNR / SSIM | training frames PSNR / SSIM | eyes | brows | mouth | jaw | all | blink corr. | gaze corr. x / y | creation (min) | receiver 256² fps / p95 ms |",
     "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
for x in rows:
    le = x["landmark_error_iod"] or {}
    L.append(f"| {x['clip']} | {x['frames_fitted']}/{x['frames_read']} | "
             f"{f(x['landmark_disputed_frames'], 'd')} / {f(x['landmark_repaired_frames'], 'd')} | {x['test_psnr_db']:.3f} | {x['test_ssim']:.4f} | {x['worst_5pct_psnr_db']:.2f} | "
             + (f"{x['with_outline']['test_psnr_db']:.3f} / {x['with_outline']['test_ssim']:.4f} | " if "with_outline" in x else "– | ")
             + f"{x['train_psnr_db']:.2f} / {x['train_ssim']:.4f} | "
             f"{f(le.get('eyes'), '.4f')} | {f(le.get('brows'), '.4f')} | {f(le.get('mouth'), '.4f')} | "
             f"{f(le.get('jaw'), '.4f')} | {f(le.get('all'), '.4f')} | {f(x['blink_correlation'], '.2f')} | "
             f"{f(x['gaze_correlation_x'], '.2f')} / {f(x['gaze_correlation_y'], '.2f')} | {x['creation_min']:.1f} | "
             + (f"{x['receiver_256']['fps']:.1f} / {x['receiver_256']['ms_p95']:.1f} |" if "receiver_256" in x else "– |"))
regions = ("eyes", "brows", "mouth", "jaw")
L += ["", "Where an expression is lost (held-out frames): dlib's points on the true and on the avatar's picture against "
      "the fitted head's landmarks, each point's mean offset over the frames left out (dlib's points and the model's "
      "landmark embedding differ by a steady amount), over the eye distance: the truth's figure is how far the person "
      "moves off the fit's motion, the avatar's how far its picture moves off the mesh it is driven with.", "",
      "| clip | truth off the fit: " + " / ".join(regions) + " | avatar off the fit: " + " / ".join(regions) + " |",
      "|---|---|---|"]
for x in rows:
    fit = x["landmarks_against_fit"] or {}
    cell = lambda k: " / ".join(f((fit.get(k) or {}).get(r), ".4f") for r in regions)
    L.append(f"| {x['clip']} | {cell('truth_vs_fit_moving')} | {cell('avatar_vs_fit_moving')} |")
L += [] if not render else ["", "Receiver: each clip's avatar in the table (`headcast-avatar render AVATAR --head-model ict.npz --display none --pacing none --threads 2 --synthetic 150`); "
      "a random avatar of the default subject configuration (headcast-bench render --head-model ict.npz: surface texture with its conditioned branch and expression blendshapes, bounded matte, frames carrying a skin colour to match): " +
      "; ".join(f"{r}²: {v['fps_median']:.1f} fps median, p95 {v['ms_p95']:.1f} ms ({v['threads']} threads, {v['head_model']}, {v['expressions']} expression coefficients)"
                for r, v in render.items())]
open(os.path.join(out, "four_clips.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
EOF
