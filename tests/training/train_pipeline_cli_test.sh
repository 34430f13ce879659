#!/usr/bin/env bash
# The avatar pipeline as a user runs it, on tiny settings: prep (the sender's
# tracker on a rendered sequence of a known subject) -> pretrain -> subject
# (identity from headcast-fit-mesh) -> resume -> eval; then the bad inputs.
set -u
bin=$1 src=$2 python=${3:-/usr/bin/python3}
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT
json() { "$python" -c "import json,sys; j=json.load(open('$1')); print($2)" 2>/dev/null; }

"$bin/headcast-headmodel" render-rgbd builtin --out "$tmp/seq" --frames 36 --size 320 --shape 0=0.8 > /dev/null 2>&1
"$bin/headcast-train" prep --input "$tmp/seq" --out "$tmp/ds" --resolutions 128 --test-frames 8 --no-calibrate \
  > "$tmp/prep.json" 2> "$tmp/prep.err"
fitted=$(json "$tmp/ds/dataset.json" "j['frames_fitted']")
crops=$(ls "$tmp/ds/128/images" 2>/dev/null | wc -l)
masks=$(ls "$tmp/ds/128/masks" 2>/dev/null | wc -l)
[ "${fitted:-0}" -ge 34 ] && [ "$crops" -eq "$fitted" ] && [ "$masks" -eq "$fitted" ] &&
  [ "$(json "$tmp/ds/dataset.json" "j['split']['test']")" = 8 ] && [ -s "$tmp/ds/preview.mp4" ] &&
  ok "prep: $fitted of 36 frames fitted, cropped, masked; 8 test frames; preview video" ||
  bad "prep: fitted=$fitted crops=$crops masks=$masks $(tail -3 "$tmp/prep.err")"

"$bin/headcast-train" prep --input "$tmp/seq" --out "$tmp/ds" --resolutions 128 --test-frames 8 --no-calibrate \
  --resume > /dev/null 2> "$tmp/prep2.err" && grep -q "reusing the finished tracking pass" "$tmp/prep2.err" &&
  [ "$(json "$tmp/ds/dataset.json" "j['frames_fitted']")" = "$fitted" ] &&
  ok "prep --resume reuses the finished tracking pass" || bad "prep resume: $(tail -2 "$tmp/prep2.err")"

# The same tracking pass with GrabCut's masks steadied over two frames either side.
cp -r "$tmp/ds" "$tmp/ds_steady"
"$bin/headcast-train" prep --input "$tmp/seq" --out "$tmp/ds_steady" --resolutions 128 --test-frames 8 \
  --no-calibrate --resume --steady-masks 2 > /dev/null 2> "$tmp/prep3.err" &&
  [ "$(json "$tmp/ds_steady/dataset.json" "j['tracking']['steady_masks']")" = 2 ] &&
  steady_iou=$("$python" - "$tmp/ds/128/masks" "$tmp/ds_steady/128/masks" <<'EOF'
import os, sys
from matplotlib.image import imread
own, steady = sys.argv[1], sys.argv[2]
ious = [((imread(os.path.join(own, n)) > 0.5) & (imread(os.path.join(steady, n)) > 0.5)).sum() /
        max(1, ((imread(os.path.join(own, n)) > 0.5) | (imread(os.path.join(steady, n)) > 0.5)).sum())
        for n in sorted(os.listdir(own))]
print(f"{min(ious):.3f}" if ious and len(ious) == len(os.listdir(steady)) else "none")
EOF
) && "$python" -c "import sys; sys.exit(0 if float('$steady_iou') > 0.95 else 1)" 2>/dev/null &&
  ok "prep --steady-masks 2: recorded, every mask within IoU $steady_iou of its own" ||
  bad "prep --steady-masks: iou=${steady_iou:-?} $(tail -2 "$tmp/prep3.err")"

# The hair's outline in the anchor's refits (the colour frames alone: the anchor
# needs a recorded RGB input). The rendered head has no hair and its head mask's
# region cuts the skull, so the outline is seen but not held.
"$bin/headcast-train" prep --input "$tmp/seq/rgb" --out "$tmp/ds_outline" --resolutions 128 --test-frames 8 \
  --no-calibrate --outline-hold 1 > /dev/null 2> "$tmp/prep4.err" &&
  [ "$(json "$tmp/ds_outline/dataset.json" "j['tracking']['outline_hold']")" = 1.0 ] &&
  [ "$(json "$tmp/ds_outline/track_report.json" "[(r['outline']['held'], r['outline']['hair_thickness_mm'] < -5) for r in j['photometric_anchor']['rounds']]")" = "[(False, True), (False, True)]" ] &&
  ok "prep --outline-hold 1: recorded; a mask top $(json "$tmp/ds_outline/track_report.json" "round(j['photometric_anchor']['rounds'][0]['outline']['hair_thickness_mm'])") mm off the skull's is not held" ||
  bad "prep --outline-hold: $(tail -2 "$tmp/prep4.err")"

"$bin/headcast-train" pretrain --resolution 128 --iterations 12 --batch 2 --eval 2 --out "$tmp/general.hcavatar" \
  > /dev/null 2>&1 && ok "pretrain (tiny)" || bad "pretrain"
# Continued on real frames: the general model's own sizes, the dataset's training split.
"$bin/headcast-train" pretrain --resolution 128 --iterations 2 --batch 2 --eval 2 --init "$tmp/general.hcavatar" \
  --real "$tmp/ds" --out "$tmp/general2.hcavatar" --json "$tmp/g2.json" > /dev/null 2> "$tmp/g2.err" &&
  [ "$(json "$tmp/g2.json" "j['mix']['train_frames'] == [$fitted - 8] and 'real frames' in j['stage']")" = True ] &&
  ok "pretrain --init continues a general model, mixed with a dataset's training frames" ||
  bad "pretrain --init --real: $(tail -2 "$tmp/g2.err")"
out=$("$bin/headcast-train" pretrain --init "$tmp/general.hcavatar" --real "$tmp/ds" --real "$tmp/ds" \
  --out "$tmp/x.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "given twice" <<<"$out" && ok "pretrain: a dataset given twice refused" ||
  bad "pretrain --real twice: $out"
out=$("$bin/headcast-train" pretrain --init "$tmp/general.hcavatar" --mlp-width 32 --out "$tmp/x.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "sizes a new network" <<<"$out" && ok "pretrain --init: a network size refused" ||
  bad "pretrain --init --mlp-width: $out"

# Data parallel: two processes on loopback train what one process trains with the whole batch.
dp=(pretrain --resolution 128 --iterations 6 --batch 4 --eval 3 --seed 5)
port=$((20000 + $$ % 20000))
"$bin/headcast-train" "${dp[@]}" --out "$tmp/one.hcavatar" --json "$tmp/one.json" > /dev/null 2>&1
"$bin/headcast-train" "${dp[@]}" --world-size 2 --rank 1 --master-port $port --out "$tmp/r1.hcavatar" > /dev/null 2>&1 &
"$bin/headcast-train" "${dp[@]}" --world-size 2 --rank 0 --master-port $port --out "$tmp/two.hcavatar" \
  --json "$tmp/two.json" > /dev/null 2> "$tmp/dp.err"
wait
same=$(json "$tmp/two.json" "abs(j['eval']['psnr_db'] - json.load(open('$tmp/one.json'))['eval']['psnr_db']) < 1e-3 and abs(j['fit']['final_loss'] / json.load(open('$tmp/one.json'))['fit']['final_loss'] - 1) < 1e-4 and j['fit']['processes'] == 2")
[ "$same" = True ] && [ ! -e "$tmp/r1.hcavatar" ] &&
  ok "two processes (c10d/Gloo over 127.0.0.1) = one process with the combined batch (loss, held-out PSNR)" ||
  bad "data parallel: $same $(tail -3 "$tmp/dp.err")"
# --processes 2 starts the second rank itself (one thread each) and trains the same.
"$bin/headcast-train" "${dp[@]}" --processes 2 --out "$tmp/p2.hcavatar" --json "$tmp/p2.json" > "$tmp/p2.out" 2> "$tmp/p2.err"
same=$(json "$tmp/p2.json" "abs(j['eval']['psnr_db'] - json.load(open('$tmp/one.json'))['eval']['psnr_db']) < 1e-3 and abs(j['fit']['final_loss'] / json.load(open('$tmp/one.json'))['fit']['final_loss'] - 1) < 1e-4 and j['fit']['processes'] == 2 and j['fit']['threads_per_process'] == 1")
[ "$same" = True ] && [ "$(grep -c '"psnr_db"' "$tmp/p2.out")" = 1 ] && ! pgrep -f "$tmp/p2.hcavatar" > /dev/null &&
  ok "--processes 2: the same training, one report, no rank left running" || bad "--processes: $same $(tail -3 "$tmp/p2.err")"
out=$("$bin/headcast-train" "${dp[@]}" --processes 2 --world-size 2 --out "$tmp/p3.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "does not go with --world-size" <<<"$out" && ok "--processes with --world-size refused" ||
  bad "--processes --world-size: $out"

"$bin/headcast-headmodel" export builtin --out "$tmp/scan.obj" --shape 0=0.8 > /dev/null 2>&1
"$bin/headcast-fit-mesh" --mesh "$tmp/scan.obj" --out "$tmp/params.json" --fit shape > /dev/null 2>&1
subject=(subject --general "$tmp/general.hcavatar" --data "$tmp/ds" --resolution 128 --batch 2 --eval 4
         --eval-every 10 --identity-from "$tmp/params.json" --out "$tmp/s.hcavatar" --log-csv "$tmp/s.csv"
         --eval-csv "$tmp/s_eval.csv" --plots "$tmp/plots" --json "$tmp/s.json" --checkpoint-dir "$tmp/ckpt"
         --checkpoint-every 10)
"$bin/headcast-train" "${subject[@]}" --iterations 20 > /dev/null 2> "$tmp/s.err" &&
  [ -s "$tmp/plots/losses.png" ] && [ -s "$tmp/plots/psnr.png" ] &&
  [ "$(tail -n +2 "$tmp/s_eval.csv" | wc -l)" -eq 2 ] && [ "$(tail -n +2 "$tmp/s.csv" | wc -l)" -eq 20 ] &&
  ok "subject: 20 steps logged, test PSNR at 10 and 20, plots" || bad "subject: $(tail -3 "$tmp/s.err")"
beta0=$(json "$tmp/params.json" "j['shape'][0]")
json "$tmp/s.json" "j['identity']" | grep -q "headcast-fit-mesh" && awk "BEGIN{exit !($beta0 > 0.7 && $beta0 < 0.9)}" &&
  ok "identity from headcast-fit-mesh (beta0 $beta0)" || bad "identity: $(json "$tmp/s.json" "j['identity']") $beta0"
"$bin/headcast-train" "${subject[@]}" --iterations 30 --resume > /dev/null 2> "$tmp/r.err" &&
  [ "$(json "$tmp/s.json" "j['fit']['first_step']")" = 20 ] && [ "$(tail -n +2 "$tmp/s.csv" | wc -l)" -eq 30 ] &&
  ok "subject resumed at step 20, log continued to 30" || bad "resume: $(tail -3 "$tmp/r.err")"

"$bin/headcast-train" eval --avatar "$tmp/s.hcavatar" --data "$tmp/ds" --out "$tmp/ev" --drive "$tmp/ds/params.hcrec" \
  --orbit-frames 6 > /dev/null 2> "$tmp/e.err"
same=$(json "$tmp/ev/eval.json" "abs(j['eval']['psnr_db'] - json.load(open('$tmp/s.json'))['eval']['psnr_db']) < 1e-4")
[ "$same" = True ] && [ "$(tail -n +2 "$tmp/ev/per_frame.csv" | wc -l)" -eq 8 ] && [ -s "$tmp/ev/side_by_side.mp4" ] &&
  [ -s "$tmp/ev/orbit.mp4" ] && [ -s "$tmp/ev/transfer.mp4" ] &&
  ok "eval: PSNR $(json "$tmp/ev/eval.json" "round(j['eval']['psnr_db'],2)") dB as the trainer measured, 8 frames, 3 videos" ||
  bad "eval: same=$same $(tail -3 "$tmp/e.err")"

# headcast-bench refine scores the held-out frames as eval does (its "before" is eval's PSNR) and refuses
# a folder that is no dataset.
"$bin/headcast-bench" refine --avatar "$tmp/s.hcavatar" --data "$tmp/ds" --every 4 --iterations 3 --causal-every 2 \
  --causal-iterations 1 --write-frames "$tmp/rf" --json "$tmp/refine.json" > /dev/null 2> "$tmp/refine.err"
same=$(json "$tmp/refine.json" "abs(j['causal']['before']['psnr_db'] - json.load(open('$tmp/ev/eval.json'))['eval']['psnr_db']) < 1e-3 and j['per_frame']['frames'] == 2 and j['causal']['frames'] == 8 and all(0 < j[k]['after']['psnr_db'] < 100 for k in ('per_frame', 'causal')) and len(j['per_frame']['frames_refined'][0]['largest_offsets']) == 6")
out=$("$bin/headcast-bench" refine --avatar "$tmp/s.hcavatar" --data "$tmp/no-dataset" 2>&1); rc=$?
written=$(ls "$tmp/rf/before" "$tmp/rf/after" | grep -c '_0000[04].png')
[ "$same" = True ] && [ $rc -ne 0 ] && echo "$out" | grep -q "no-dataset" && [ "$written" = 8 ] &&
  ok "bench refine: eval's PSNR before, 2 frames alone (written before and after) and 8 in order; a missing dataset refused" ||
  bad "bench refine: same=$same rc=$rc written=$written $(json "$tmp/refine.json" "(j['causal']['before'], j['per_frame']['frames'], j['per_frame']['after'])") eval $(json "$tmp/ev/eval.json" "j['eval']['psnr_db']") $out"
# A calibration window: refined on the first frames only, the frames after it scored apart; a window as long as
# the frames is the plain causal schedule.
for until in 4 8; do
  "$bin/headcast-bench" refine --avatar "$tmp/s.hcavatar" --data "$tmp/ds" --every 8 --iterations 0 --causal-every 2 \
    --causal-iterations 1 --causal-until $until --json "$tmp/refine_u$until.json" > /dev/null 2>&1
done
window=$(json "$tmp/refine_u4.json" "(j['causal']['until'], j['causal']['after_the_window']['frames'], 0 < j['causal']['after_the_window']['after']['psnr_db'] < 100)")
whole=$(json "$tmp/refine_u8.json" "'after_the_window' not in j['causal'] and abs(j['causal']['after']['psnr_db'] - json.load(open('$tmp/refine.json'))['causal']['after']['psnr_db']) < 1e-6")
[ "$window" = "(4, 4, True)" ] && [ "$whole" = True ] &&
  ok "bench refine --causal-until: 4 frames after a 4-frame window scored apart; a window of all 8 is the causal schedule" ||
  bad "bench refine --causal-until: window=$window whole=$whole"

# Short videos: frames interpolated between consecutive training frames, used by subject unless told not to.
"$bin/headcast-train" prep --input "$tmp/seq" --out "$tmp/dsi" --resolutions 128 --test-frames 8 --no-calibrate \
  --max-frames 20 --interpolate 1 > /dev/null 2>&1
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --out "$tmp/i.hcavatar" --json "$tmp/i.json" > /dev/null 2>&1
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --no-interpolated --out "$tmp/n.hcavatar" --json "$tmp/n.json" > /dev/null 2>&1
interp=$(ls "$tmp/dsi/128/interp/images" 2>/dev/null | wc -l)
[ "$interp" -eq 11 ] && [ "$(json "$tmp/i.json" "j['interpolated_frames']")" = 11 ] &&
  [ "$(json "$tmp/n.json" "j['interpolated_frames']")" = 0 ] && [ "$(json "$tmp/i.json" "j['eval']['frames']")" = 8 ] &&
  ok "interpolation: 11 in-between frames for 12 training frames, trained on, never tested on" ||
  bad "interpolation: $interp frames, $(json "$tmp/i.json" "j['interpolated_frames']")"

# A subject's texture branch is conditioned per frame, has 64² expression blendshapes held back by a decay of 0.5,
# and its CNeRF samples are canonical with the covered parts apart by default (the general model has head-frame
# samples); without a texture or canonical samples there is nothing to condition, add to or carry apart, and asking
# for both is refused.
# --surface-features 0 --no-canonical-samples is the thesis's avatar.
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --surface-features 0 --no-canonical-samples --hair-margin 3 --out "$tmp/t.hcavatar" > /dev/null 2> "$tmp/t.err"
config() { "$python" -c "import json,zipfile; print(json.loads(zipfile.ZipFile('$1').read('manifest.json'))['config']$2)"; }
[ "$(config "$tmp/general.hcavatar" "['canonical_samples']")" = False ] &&
  [ "$(config "$tmp/i.hcavatar" "['surface_conditioned']")" = True ] &&
  [ "$(config "$tmp/i.hcavatar" "['canonical_samples']")" = True ] &&
  [ "$(config "$tmp/i.hcavatar" "['covered_apart']")" = True ] &&
  [ "$(config "$tmp/i.hcavatar" "['surface_blend']")" = 64 ] &&
  [ "$(json "$tmp/i.json" "j['fit']['blend_decay']")" = 0.5 ] &&
  [ "$(config "$tmp/t.hcavatar" "['surface_features']")" = 0 ] &&
  [ "$(config "$tmp/t.hcavatar" "['surface_conditioned']")" = False ] &&
  [ "$(config "$tmp/t.hcavatar" "['surface_blend']")" = 0 ] &&
  [ "$(config "$tmp/t.hcavatar" "['canonical_samples']")" = False ] &&
  [ "$(config "$tmp/t.hcavatar" "['covered_apart']")" = False ] &&
  ok "subject: conditioned texture, decayed blendshapes, canonical samples with the covered parts apart by default; the thesis's flags: none" ||
  bad "subject conditioning: $(tail -3 "$tmp/t.err")"
# Which rays beside the silhouette are cast is a fine-tune's choice (not the network's size): the general model's
# margin unless --hair-margin gives one.
[ "$(config "$tmp/i.hcavatar" "['hair_margin_px']")" = "$(config "$tmp/general.hcavatar" "['hair_margin_px']")" ] &&
  [ "$(config "$tmp/t.hcavatar" "['hair_margin_px']")" = 3 ] &&
  ok "subject --hair-margin: the general model's margin by default, 3 when asked" ||
  bad "hair margin: $(config "$tmp/i.hcavatar" "['hair_margin_px']") / $(config "$tmp/t.hcavatar" "['hair_margin_px']")"
# A subject's optimiser: twice pretraining's rate, reached over a 200-step warm-up (pretraining: none).
[ "$(json "$tmp/i.json" "j['fit']['learning_rate'] == 0.004 and j['fit']['warmup_steps'] == 200")" = True ] &&
  [ "$(json "$tmp/two.json" "j['fit']['learning_rate'] == 0.002 and j['fit']['warmup_steps'] == 0")" = True ] &&
  ok "subject: rate 0.004 after a 200-step warm-up by default; pretrain 0.002 without" ||
  bad "subject rate: $(json "$tmp/i.json" "j['fit']")"
# Synthetic renders blind in the face regions: the first step's samples are all synthetic (start 1), its loss finite.
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --synthetic-start 1 --blind-synthetic-face --out "$tmp/b.hcavatar" --json "$tmp/b.json" \
  > /dev/null 2> "$tmp/b.err"
[ "$(json "$tmp/b.json" "j['synthetic_mix']['face_regions']")" = "not learned from them" ] &&
  [ "$(json "$tmp/i.json" "j['synthetic_mix']['face_regions']")" = "learned from them" ] &&
  [ "$(json "$tmp/b.json" "j['fit']['region_weight']")" = 4.0 ] &&
  [ "$(json "$tmp/b.json" "0 < j['fit']['final_loss'] < 10")" = True ] &&
  ok "subject --blind-synthetic-face: trained and recorded" || bad "blind synthetic face: $(tail -3 "$tmp/b.err")"
# The texture into the level before the last too: trained and kept in the file (the default: the last only).
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --surface-levels 2 --out "$tmp/l.hcavatar" --json "$tmp/l.json" > /dev/null 2> "$tmp/l.err"
[ "$(config "$tmp/l.hcavatar" "['surface_levels']")" = 2 ] && [ "$(config "$tmp/i.hcavatar" "['surface_levels']")" = 1 ] &&
  [ "$(json "$tmp/l.json" "0 < j['fit']['final_loss'] < 10")" = True ] &&
  ok "subject --surface-levels 2: trained and kept" || bad "surface levels: $(tail -3 "$tmp/l.err")"
# The offsets' mean kept as the avatar's conditioning bias (--mean-offset): its size is the one the run reports;
# without the flag, none.
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --mean-offset --out "$tmp/m.hcavatar" --json "$tmp/m.json" > /dev/null 2> "$tmp/m.err"
bias_norm=$("$python" -c "import json, math, zipfile
b = json.loads(zipfile.ZipFile('$tmp/m.hcavatar').read('manifest.json'))['config']['conditioning_bias']
print(math.sqrt(sum(v * v for v in b['geometry'] + b['appearance'])))" 2> /dev/null)
[ -n "$bias_norm" ] && [ "$(json "$tmp/m.json" "0 < $bias_norm and abs(j['fit']['offsets']['mean_norm'] - $bias_norm) < 1e-4 * $bias_norm")" = True ] &&
  [ "$(config "$tmp/i.hcavatar" ".get('conditioning_bias')")" = None ] &&
  ok "subject --mean-offset: the offsets' mean kept as the conditioning bias; by default none" ||
  bad "mean offset: bias norm '$bias_norm', $(json "$tmp/m.json" "j['fit'].get('offsets')") $(tail -3 "$tmp/m.err")"
# The expression span: a subject records each coefficient's extremes over its training frames (all but the last 8),
# --no-expression-span none; eval tells the networks within the avatar's span, none, or the dataset's.
"$bin/headcast-rec" export "$tmp/dsi/params.hcrec" --out "$tmp/dsi_params.json" > /dev/null 2>&1
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --no-expression-span --out "$tmp/ns.hcavatar" --json "$tmp/ns.json" > /dev/null 2> "$tmp/ns.err"
span_ok=$("$python" - "$tmp/i.hcavatar" "$tmp/dsi_params.json" <<'PY' 2>&1
import json, sys, zipfile
span = json.loads(zipfile.ZipFile(sys.argv[1]).read('manifest.json'))['config']['expression_span']
frames = json.load(open(sys.argv[2]))['frames'][:-8]
e = [f['expression'] for f in frames]
low = [min(x[k] for x in e) for k in range(len(e[0]))]
high = [max(x[k] for x in e) for k in range(len(e[0]))]
ok = len(span['low']) == len(low) and all(abs(a - b) < 1e-6 for a, b in zip(span['low'] + span['high'], low + high))
print(ok and any(h > l for l, h in zip(low, high)))
PY
)
[ "$span_ok" = True ] && [ "$(config "$tmp/ns.hcavatar" ".get('expression_span')")" = None ] &&
  json "$tmp/ns.json" "j['expression_span']" | grep -q "^none" &&
  ok "subject: the training frames' expression span kept in the avatar; --no-expression-span none" ||
  bad "expression span: $span_ok $(tail -2 "$tmp/ns.err")"
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --expression-span-in-training --out "$tmp/st.hcavatar" --json "$tmp/st.json" > /dev/null 2> "$tmp/st.err"
out=$("$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 \
  --iterations 2 --expression-span-in-training --no-expression-span --out "$tmp/st2.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "expression-span-in-training needs the span kept" <<<"$out" &&
  [ "$(config "$tmp/st.hcavatar" "['expression_span'] == json.loads(zipfile.ZipFile('$tmp/i.hcavatar').read('manifest.json'))['config']['expression_span']")" = True ] &&
  json "$tmp/st.json" "j['expression_span']" | grep -q "from the first step" &&
  ok "subject --expression-span-in-training: the same span, from the first step; without a span refused" ||
  bad "span in training: $out $(tail -2 "$tmp/st.err")"
said() {  # said AVATAR HOW: the first words of eval.json's expression_span
  "$bin/headcast-train" eval --avatar "$tmp/$1.hcavatar" --data "$tmp/dsi" --out "$tmp/es_$1_$2" --orbit-frames 0 \
    --no-landmarks --expression-span "$2" > /dev/null 2>&1
  json "$tmp/es_$1_$2/eval.json" "' '.join(j['expression_span'].split()[:2])"
}
spans="$(said i avatar) | $(said i none) | $(said ns dataset)"
[ "$spans" = "the avatar's | none: the | the dataset's" ] &&
  ok "eval --expression-span avatar|none|dataset: said in eval.json" || bad "eval spans: '$spans'"
# The matte's scale: a subject writes its default (the one --help shows) or --matte-scale's into the file and its
# report; eval draws at the avatar's unless --matte-scale says otherwise, and says which; a scale out of range, or
# one for an avatar without a matte, is refused.
default_scale=$("$bin/headcast-train" subject --help | sed -n 's/.*--matte-scale FLOAT=\([0-9.]*\).*/\1/p')
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --eval 2 --matte-scale 0.8 --out "$tmp/ms.hcavatar" --json "$tmp/ms.json" > /dev/null 2> "$tmp/ms.err"
"$bin/headcast-train" eval --avatar "$tmp/i.hcavatar" --data "$tmp/dsi" --out "$tmp/ems" --orbit-frames 0 \
  --no-landmarks --matte-scale 0.7 > /dev/null 2>&1
scales="$(config "$tmp/i.hcavatar" "['matte_scale'] == $default_scale") $(json "$tmp/i.json" "j['matte_scale'] == $default_scale")"
scales+=" $(config "$tmp/ms.hcavatar" "['matte_scale']") $(json "$tmp/ms.json" "j['matte_scale']")"
scales+=" $(json "$tmp/es_i_avatar/eval.json" "j['matte_scale']['value'] == $default_scale and j['matte_scale']['from']")"
scales+=" $(json "$tmp/ems/eval.json" "(j['matte_scale']['value'], j['matte_scale']['from'])")"
out=$("$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 \
  --iterations 2 --matte-scale 0 --out "$tmp/ms0.hcavatar" 2>&1)
refused_zero=$?
out2=$("$bin/headcast-train" eval --avatar "$tmp/general.hcavatar" --data "$tmp/dsi" --out "$tmp/emg" --orbit-frames 0 \
  --no-landmarks --matte-scale 0.5 2>&1)
refused_plain=$?
[ -n "$default_scale" ] && [ "$scales" = "True True 0.8 0.8 the avatar (0.7, '--matte-scale')" ] &&
  [ "$(config "$tmp/general.hcavatar" "['matte']")" = none ] &&
  [ $refused_zero -ne 0 ] && grep -qi "matte.scale" <<<"$out" && [ $refused_plain -ne 0 ] && grep -q "no matte" <<<"$out2" &&
  ok "subject --matte-scale: the default ($default_scale) or the given scale kept; eval draws at it or at --matte-scale; bad scales refused" ||
  bad "matte scale: '$default_scale' '$scales' $refused_zero '$(tail -1 <<<"$out")' $refused_plain '$(tail -1 <<<"$out2")' $(tail -2 "$tmp/ms.err")"
# Motion blur: a subject with --motion-blur learns the exposure from that start and keeps what it learnt in the file
# and its report; eval draws at the avatar's exposure unless --motion-blur says otherwise, and says which; an
# exposure out of range is refused by both.
"$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 --iterations 2 \
  --motion-blur 0.5 --exposure-rate 0.05 --out "$tmp/mb.hcavatar" --json "$tmp/mb.json" > /dev/null 2> "$tmp/mb.err"
for how in avatar 0; do
  flag=(); [ "$how" = avatar ] || flag=(--motion-blur "$how")
  "$bin/headcast-train" eval --avatar "$tmp/mb.hcavatar" --data "$tmp/dsi" --out "$tmp/emb_$how" --orbit-frames 0 \
    --no-landmarks "${flag[@]}" > /dev/null 2>&1
done
learnt=$(json "$tmp/mb.json" "j['fit']['motion_blur']['exposure_learnt']")
blur="$(config "$tmp/mb.hcavatar" "['motion_blur'] == $learnt")"
blur+=" $(json "$tmp/emb_avatar/eval.json" "(j['motion_blur']['exposure'] == $learnt, j['motion_blur']['from'])")"
blur+=" $(json "$tmp/emb_0/eval.json" "(j['motion_blur']['exposure'], j['motion_blur']['from'])")"
blur+=" $(config "$tmp/i.hcavatar" "['motion_blur']")"
refuses() {  # refuses PATTERN COMMAND...: the command fails and says PATTERN
  local pattern=$1 said
  shift
  said=$("$@" 2>&1) && return 1
  grep -q "$pattern" <<<"$said"
}
refuses "motion.blur" "$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" \
  --resolution 128 --iterations 2 --motion-blur 2.5 --out "$tmp/mb2.hcavatar"
refused_subject=$?
refuses "motion.blur" "$bin/headcast-train" eval --avatar "$tmp/mb.hcavatar" --data "$tmp/dsi" --out "$tmp/emb3" \
  --orbit-frames 0 --no-landmarks --motion-blur 3
refused_eval=$?
[ "$blur" = "True (True, 'the avatar') (0.0, '--motion-blur') 0.0" ] && [ $refused_subject -eq 0 ] &&
  [ $refused_eval -eq 0 ] &&
  ok "subject --motion-blur: the exposure learnt ($learnt) kept in the file and the report; eval draws at it or at --motion-blur; out of range refused" ||
  bad "motion blur: '$learnt' '$blur' refused (0: yes) $refused_subject $refused_eval $(tail -2 "$tmp/mb.err")"
out=$("$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 \
  --iterations 2 --surface-levels 4 --out "$tmp/l4.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "surface-levels" <<<"$out" && ok "--surface-levels 4 refused" || bad "surface levels 4: $out"
out=$("$bin/headcast-train" subject --general "$tmp/general.hcavatar" --data "$tmp/dsi" --resolution 128 \
  --iterations 2 --surface-features 0 --surface-conditioned --out "$tmp/u.hcavatar" 2>&1)
[ $? -ne 0 ] && grep -q "surface-conditioned needs --surface-features" <<<"$out" &&
  ok "--surface-conditioned without a texture refused" || bad "conditioned without texture: $out"

# eval --split train: the real training frames only (never the in-between ones); a bad split is refused.
"$bin/headcast-train" eval --avatar "$tmp/i.hcavatar" --data "$tmp/dsi" --out "$tmp/evt" --split train \
  --orbit-frames 0 > /dev/null 2> "$tmp/evt.err"
[ "$(json "$tmp/evt/eval.json" "j['eval']['frames']")" = 12 ] &&
  [ "$(json "$tmp/evt/eval.json" "j['eval']['on']")" = "training frames" ] &&
  ok "eval --split train: the 12 real training frames" || bad "eval --split train: $(tail -3 "$tmp/evt.err")"
out=$("$bin/headcast-train" eval --avatar "$tmp/i.hcavatar" --data "$tmp/dsi" --out "$tmp/evx" --split all 2>&1)
[ $? -ne 0 ] && grep -q "split" <<<"$out" && ok "eval --split all refused" || bad "split all: $out"

# Bad inputs: clear errors, exit status 1.
refused() {  # refused WHAT EXPECTED-TEXT COMMAND...
  local what=$1 expected=$2
  shift 2
  out=$("$@" 2>&1); rc=$?
  [ $rc -ne 0 ] && grep -q "$expected" <<<"$out" && ok "refused: $what" || bad "$what (rc $rc): $(tail -2 <<<"$out")"
}
mkdir -p "$tmp/empty" "$tmp/black"
refused "empty folder" "no images" "$bin/headcast-train" prep --input "$tmp/empty" --out "$tmp/x1" --no-calibrate
"$python" - "$tmp/black" <<'EOF'
import struct, sys, zlib
# 64x64 black RGB PNGs: no face anywhere.
def png(w, h):
    raw = b"".join(b"\0" + b"\0" * 3 * w for _ in range(h))
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) + \
        chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
for i in (1, 2, 3):
    open(f"{sys.argv[1]}/{i}.png", "wb").write(png(64, 64))
EOF
refused "video with no face" "no face" "$bin/headcast-train" prep --input "$tmp/black" --out "$tmp/x2" --no-calibrate
refused "steady masks beyond the limit" "steady-masks must be in" \
  "$bin/headcast-train" prep --input "$tmp/seq" --out "$tmp/x4" --no-calibrate --steady-masks 9
refused "the outline held without the photometric anchor" "outline-hold needs the photometric anchor" \
  "$bin/headcast-train" prep --input "$tmp/seq/rgb" --out "$tmp/x5" --no-calibrate --photometric-anchor 0 --outline-hold 1
refused "too few frames for the split" "test frames" \
  "$bin/headcast-train" prep --input "$tmp/seq" --out "$tmp/x3" --no-calibrate --max-frames 10 --test-frames 8
echo garbage > "$tmp/ckpt/$(cat "$tmp/ckpt/LATEST")/state.json"
refused "corrupt checkpoint" "cannot resume" "$bin/headcast-train" "${subject[@]}" --iterations 40 --resume
refused "missing resolution" "no 256 crops" "$bin/headcast-train" subject --general "$tmp/general.hcavatar" \
  --data "$tmp/ds" --resolution 256 --iterations 2 --out "$tmp/x.hcavatar"
echo "not a recording" > "$tmp/foreign.hcrec"
refused "foreign drive recording" "foreign.hcrec" \
  "$bin/headcast-train" eval --avatar "$tmp/s.hcavatar" --data "$tmp/ds" --out "$tmp/ev2" --drive "$tmp/foreign.hcrec"
ict=${HEADCAST_DATA:-$src/../shared/data}/head-models/ict-facekit
if [ -d "$ict" ]; then
  "$bin/headcast-headmodel" convert ict --folder "$ict" --out "$tmp/ict.npz" > /dev/null 2>&1
  refused "dataset and avatar of another head model" "prepared for head model" "$bin/headcast-train" subject \
    --head-model "$tmp/ict.npz" --general "$tmp/general.hcavatar" --data "$tmp/ds" --resolution 128 --out "$tmp/y.hcavatar"
  refused "avatar of another head model" "head model" "$bin/headcast-train" pretrain --head-model "$tmp/ict.npz" \
    --init "$tmp/general.hcavatar" --iterations 1 --out "$tmp/z.hcavatar"
else
  echo "skip: no ICT-FaceKit folder ($ict): the other-head-model checks"
fi
checks_summary "train pipeline cli"
