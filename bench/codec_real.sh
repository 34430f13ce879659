#!/usr/bin/env bash
# The parameter codec on real people's tracks (issue #25): every talking-head
# clip in the shared data tracked with ICT-FaceKit (headcast-track --calibrate),
# then `headcast-bench codec` on each: bits per frame at the wide-link key-frame
# interval (30 frames) and the narrow-link one (10 s = 300 frames), at each
# quantisation error given; with --avatars, the PSNR the quantisation costs on
# each clip's held-out frames through that person's avatar.
#   bench/codec_real.sh OUT [--ict DIR] [--clips "d9 d10 d14 d3"] [--errors "2e-4 3e-4"]
#       [--avatars DIR]   a bench/four_clips.sh output (ict.npz, ds_CLIP/, avatar_CLIP.hcavatar;
#                         a clip without its avatar there gets no PSNR cost)
# Writes OUT/codec_real.{json,md} and prints the table. Tracks and PSNR costs
# already in OUT are reused (a later run can add clips or avatars).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/script_start.sh"
name=codec_real ict=$data/head-models/ict-facekit clips="d9 d10 d14 d3" errors="2e-4" avatars=""
while [ $# -gt 0 ]; do
  case $1 in
    --ict) ict=$2; shift 2 ;;
    --clips) clips=$2; shift 2 ;;
    --errors) errors=$2; shift 2 ;;
    --avatars) avatars=$2; shift 2 ;;
    *) echo "$name: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$out"
out=$(cd "$out" && pwd)
source "$root/bench/avatar_runs.sh"
model=$out/ict.npz
if [ -n "$avatars" ]; then
  model=$avatars/ict.npz  # the avatars' own model (the same conversion)
  [ -f "$model" ] || { echo "$name: no $model" >&2; exit 2; }
else
  [ -f "$model" ] || { step "ICT-FaceKit -> npz"; run convert.log "$bin/headcast-headmodel" convert ict --folder "$ict" --out "$model"; }
fi
for clip in $clips; do
  [ -f "$out/$clip.hcrec" ] || { step "$clip: track"; run "track_$clip.log" "$bin/headcast-track" \
    --input "$data/video/talking_$clip.mp4" --head-model "$model" --calibrate --out "$out/$clip.hcrec"; }
  for e in $errors; do
    for k in 30 300; do
      step "$clip: codec, error $e m, key every $k"
      run "codec_${clip}_${e}_$k.log" "$bin/headcast-bench" codec --recording "$out/$clip.hcrec" --head-model "$model" \
        --quantisation-error "$e" --key-interval "$k" --json "$out/codec_${clip}_${e}_$k.json"
    done
    if [ -n "$avatars" ] && [ ! -f "$avatars/avatar_$clip.hcavatar" ]; then
      step "$clip: no avatar in $avatars, no PSNR cost"
    elif [ -n "$avatars" ]; then
      step "$clip: PSNR cost through the avatar, error $e m"
      [ -f "$out/cost_${clip}_$e.json" ] || run "cost_${clip}_$e.log" "$bin/headcast-bench" codec --recording "$out/$clip.hcrec" --head-model "$model" \
        --quantisation-error "$e" --key-interval 300 --avatar "$avatars/avatar_$clip.hcavatar" \
        --data "$avatars/ds_$clip" --json "$out/cost_${clip}_$e.json"
    fi
  done
done
"$python" - "$out" "$command" "$clips" "$errors" <<'PY'
import json, os, sys
out, command, clips, errors = sys.argv[1], sys.argv[2], sys.argv[3].split(), sys.argv[4].split()
rows = []
for c in clips:
    for e in errors:
        j = {k: json.load(open(os.path.join(out, f"codec_{c}_{e}_{k}.json"))) for k in (30, 300)}
        r = {"clip": f"talking_{c}", "quantisation_error_mm": float(e) * 1e3, "frames": j[30]["frames"],
             "bits_per_frame_key30": j[30]["bits_per_frame_mean"], "bits_per_frame_key300": j[300]["bits_per_frame_mean"],
             "bits_key_frame": j[300]["bits_per_frame_key_mean"], "bits_delta_frame": j[300]["bits_per_frame_delta_mean"],
             "values_beyond_half_a_step": j[300]["values_beyond_half_a_step"],
             "max_vertex_error_mm": j[300]["max_vertex_error_mm_max"]}
        cost = os.path.join(out, f"cost_{c}_{e}.json")
        if os.path.exists(cost):
            k = json.load(open(cost))
            r.update({x: k[x] for x in ("avatar_psnr_db_original_params", "avatar_psnr_db_decoded_params",
                                        "codec_psnr_cost_db_mean", "codec_psnr_cost_db_max",
                                        "decoded_vs_original_render_psnr_db_mean", "dataset_test_frames")})
        rows.append(r)
json.dump({"command": command, "rows": rows}, open(os.path.join(out, "codec_real.json"), "w"), indent=2)
f = lambda v, s: "–" if v is None else format(v, s)
L = [f"Made by `{command}`: ICT-FaceKit tracks (53 expression coefficients + 18 pose values per frame), "
     "ParamCodec v2. Key every 30 frames (wide links) and every 300 (narrow links, the sender's default below 32 kbit/s). "
     "PSNR cost: the avatar of that person on its 150 held-out frames, from the tracked and from the decoded "
     "parameters, against the true frames (and the two renders against each other).", "",
     "| clip | error/step (mm) | frames | bits/frame (key 30) | bits/frame (key 300) | key frame | delta frame | max vertex error (mm) | PSNR tracked → decoded (dB) | cost mean / max (dB) | decoded vs tracked render (dB) |",
     "|---|---|---|---|---|---|---|---|---|---|---|"]
for r in rows:
    psnr = (f"{r['avatar_psnr_db_original_params']:.3f} → {r['avatar_psnr_db_decoded_params']:.3f}"
            if "avatar_psnr_db_original_params" in r else "–")
    cost = (f"{r['codec_psnr_cost_db_mean']:.4f} / {r['codec_psnr_cost_db_max']:.3f}"
            if "codec_psnr_cost_db_mean" in r else "–")
    L.append(f"| {r['clip']} | {r['quantisation_error_mm']:.2f} | {r['frames']} | {r['bits_per_frame_key30']:.1f} | "
             f"{r['bits_per_frame_key300']:.1f} | {r['bits_key_frame']:.0f} | {r['bits_delta_frame']:.1f} | "
             f"{r['max_vertex_error_mm']:.2f} | {psnr} | {cost} | {f(r.get('decoded_vs_original_render_psnr_db_mean'), '.1f')} |")
open(os.path.join(out, "codec_real.md"), "w").write("\n".join(L) + "\n")
print("\n".join(L))
PY
