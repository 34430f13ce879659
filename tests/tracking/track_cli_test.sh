#!/usr/bin/env bash
# headcast-track on real video (../shared/data; skipped without it) and on bad input.
set -u
bin=$1; data=$2; python=${3:-/usr/bin/python3}
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
trap 'rm -rf "$tmp"' EXIT
"$bin/headcast-headmodel" convert ict --folder "$data/head-models/ict-facekit" --parts face,head,mouth,eyes --identity 10 \
  --out "$tmp/ict.npz" > /dev/null 2>&1 || { echo "SKIP: no ../shared/data (set HEADCAST_DATA)"; exit 77; }
"$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 60 \
  --out "$tmp/d14.hcrec" --json "$tmp/r.json" --overlay "$tmp/o.mp4" > /dev/null 2>&1
grep -q '"fitted_frames": 60' "$tmp/r.json" && ok "60 of 60 real frames fitted" || bad "fit: $(cat "$tmp/r.json")"
err=$(grep -o '"landmark_error_iod_mean": [0-9.]*' "$tmp/r.json" | awk '{print $2}')
awk "BEGIN{exit !($err < 0.03)}" && ok "landmark error $err IOD < 0.03" || bad "landmark error $err"
jit=$(grep -o '"jitter_iod_median": [0-9.]*' "$tmp/r.json" | awk '{print $2}')
raw=$(grep -o '"jitter_iod_median_raw_landmarks": [0-9.]*' "$tmp/r.json" | awk '{print $2}')
awk "BEGIN{exit !($jit < $raw && $jit < 0.015)}" && ok "fitted landmarks shake less than dlib's ($jit vs $raw IOD)" ||
  bad "jitter $jit vs raw $raw"
"$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 60 --calibrate \
  --out "$tmp/c14.hcrec" --json "$tmp/c.json" > /dev/null 2>&1
cerr=$(grep -o '"landmark_error_iod_mean": [0-9.]*' "$tmp/c.json" | awk '{print $2}')
grep -q '"focal_px"' "$tmp/c.json" && awk "BEGIN{exit !($cerr < 0.03)}" &&
  ok "identity + focal calibrated over key frames (error $cerr IOD)" || bad "calibrate: $(cat "$tmp/c.json")"
"$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 60 \
  --eye-look-prior 100 --out "$tmp/e14.hcrec" --json "$tmp/e.json" > /dev/null 2>&1
eerr=$(grep -o '"landmark_error_iod_mean": [0-9.]*' "$tmp/e.json" | awk '{print $2}')
grep -q '"fitted_frames": 60' "$tmp/e.json" && awk "BEGIN{exit !($eerr < 0.03)}" &&
  ok "--eye-look-prior 100: 60 frames fitted (error $eerr IOD)" || bad "eye-look prior: $(cat "$tmp/e.json")"
"$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 60 \
  --photometric-anchor 0.5 --out "$tmp/a14.hcrec" --json "$tmp/a.json" > /dev/null 2>&1
aerr=$(grep -o '"landmark_error_iod_mean": [0-9.]*' "$tmp/a.json" | awk '{print $2}')
refitted=$(grep -o '"frames_refitted": [0-9]*' "$tmp/a.json" | tail -1 | awk '{print $2}')
referenced=$(grep -o '"points_referenced": [0-9]*' "$tmp/a.json" | tail -1 | awk '{print $2}')
grep -q '"fitted_frames": 60' "$tmp/a.json" && awk "BEGIN{exit !($aerr < 0.03 && ${refitted:-0} >= 55 && ${referenced:-0} >= 50)}" &&
  ok "--photometric-anchor: $refitted of 60 frames fitted again to $referenced points (error $aerr IOD)" ||
  bad "photometric anchor: $(cat "$tmp/a.json")"
# The sender's rule on the same 60 frames (FrameTracker::SetAnchor): an avatar
# file carrying the clip's references, as the fine-tune writes them from prep's
# dataset, and each frame held to them as it is fitted, in one pass. Those fits
# land nearer the clip's anchored ones than the landmark fits alone do.
fp=$("$bin/headcast-rec" info "$tmp/a14.hcrec" | grep -o '"head_model_fingerprint": "[0-9a-f]*"' | cut -d'"' -f4)
"$python" - "$tmp" "$fp" <<'EOF'
import json, sys, zipfile
tmp, fp = sys.argv[1], sys.argv[2]
reference = json.load(open(tmp + '/a.json'))['photometric_anchor']['reference']
manifest = {'format': 'headcast-avatar', 'head_model': {'fingerprint': fp}, 'subject': {'shape': []}}
with zipfile.ZipFile(tmp + '/plain.hcavatar', 'w') as z:
    z.writestr('manifest.json', json.dumps(manifest))
manifest['tracking_anchor'] = reference
with zipfile.ZipFile(tmp + '/anchored.hcavatar', 'w') as z:
    z.writestr('manifest.json', json.dumps(manifest))
reference['grey'][0] = 'grey'
with zipfile.ZipFile(tmp + '/broken.hcavatar', 'w') as z:
    z.writestr('manifest.json', json.dumps(manifest))
del manifest['tracking_anchor']
manifest['tracking_fit'] = {'expression_prior': 50, 'expression_range_weight': 100, 'eye_look_prior': 0,
                            'eye_look_prior_shapes': 'vertical'}
with zipfile.ZipFile(tmp + '/fitted.hcavatar', 'w') as z:
    z.writestr('manifest.json', json.dumps(manifest))
manifest['tracking_fit']['expression_prior'] = 'much'
with zipfile.ZipFile(tmp + '/badfit.hcavatar', 'w') as z:
    z.writestr('manifest.json', json.dumps(manifest))
EOF
# An avatar's expression fit is how frames are fitted for it, unless the
# command line says otherwise; a file from before carries none (the settings of then).
fit_of() {
  "$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 2 \
    --identity-from "$tmp/$1.hcavatar" --out "$tmp/f.hcrec" --json "$tmp/f.json" "${@:2}" > /dev/null 2>&1 &&
    "$python" -c "import json; f = json.load(open('$tmp/f.json'))['expression_fit']; print(f['expression_prior'], f['eye_look_prior_shapes'])"
}
[ "$(fit_of fitted)" = "50.0 vertical" ] && [ "$(fit_of fitted --expression-prior 3)" = "3.0 all" ] &&
  [ "$(fit_of plain)" = "0.002 all" ] &&
  ok "the avatar's expression fit used for its frames; a flag given wins; an older avatar fits as then" ||
  bad "expression fit from the avatar: '$(fit_of fitted)' '$(fit_of fitted --expression-prior 3)' '$(fit_of plain)'"
out=$("$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 2 \
  --identity-from "$tmp/badfit.hcavatar" --out "$tmp/b.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "badfit.hcavatar" <<<"$out" && grep -q "tracking_fit.expression_prior wants a number" <<<"$out" &&
  ok "a malformed expression fit refused, naming the file" || bad "broken fit: rc=$rc $out"
"$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 60 \
  --identity-from "$tmp/anchored.hcavatar" --avatar-anchor --out "$tmp/l14.hcrec" --json "$tmp/l.json" > /dev/null 2>&1
for r in a14 l14 d14; do "$bin/headcast-rec" export "$tmp/$r.hcrec" --out "$tmp/$r.npz" > /dev/null 2>&1; done
cmp=$("$python" - "$tmp" <<'EOF'
import json, sys
import numpy as np
tmp = sys.argv[1]
a, l, d = (np.load(f'{tmp}/{r}.npz') for r in ('a14', 'l14', 'd14'))
def apart(x):  # mean distance of the head's origin from the clip's anchored fits, mm
    return 1e3 * np.linalg.norm(x['cam_translation'] - a['cam_translation'], axis=1).mean()
anchored = json.load(open(f'{tmp}/l.json'))['photometric_anchor']['frames_anchored']
print(anchored, round(apart(l), 2), round(apart(d), 2))
EOF
)
read -r anchored live plain <<<"${cmp:-0 9 0}"
awk "BEGIN{exit !($anchored >= 55 && $live < 0.5 * $plain)}" &&
  ok "--avatar-anchor: $anchored of 60 frames held to the avatar's references as fitted; $live mm from the clip's anchored fits (landmarks alone: $plain mm)" ||
  bad "avatar anchor: ${cmp:-none} $(head -c 600 "$tmp/l.json")"
out=$("$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 2 \
  --identity-from "$tmp/plain.hcavatar" --avatar-anchor --out "$tmp/p.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "carries no photometric anchor" <<<"$out" && ok "--avatar-anchor on an avatar without one refused" ||
  bad "avatar without anchor: rc=$rc $out"
out=$("$bin/headcast-track" --input "$data/video/talking_d14.mp4" --head-model "$tmp/ict.npz" --max-frames 2 \
  --identity-from "$tmp/broken.hcavatar" --avatar-anchor --out "$tmp/b.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "broken.hcavatar" <<<"$out" && grep -q "not a number in 0..1" <<<"$out" &&
  ok "a malformed anchor reference refused, naming the file" || bad "broken anchor: rc=$rc $out"
out=$("$bin/headcast-track" --input /dev/video97 --photometric-anchor 1 --out "$tmp/c.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "needs a recorded input" <<<"$out" && ok "--photometric-anchor on a camera refused" ||
  bad "anchor on a camera: rc=$rc $out"
out=$("$bin/headcast-track" --input "$data/video/talking_d14.mp4" --eye-look-prior -1 --out "$tmp/n.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q -- "--eye-look-prior must be >= 0" <<<"$out" && ok "negative --eye-look-prior refused by name" ||
  bad "negative prior: rc=$rc $out"
"$bin/headcast-avatar" render --help > /dev/null  # (the recording format is shared with the avatar tools)
head -c 20000 "$data/video/talking_d14.mp4" > "$tmp/cut.mp4"
out=$("$bin/headcast-track" --input "$tmp/cut.mp4" --out "$tmp/x.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -qE "cut.mp4" <<<"$out" && ok "truncated video refused by name" || bad "truncated: rc=$rc $out"
mkdir "$tmp/imgs" && echo "not an image" > "$tmp/imgs/a.png"
cp "$data/landmarks/takeo.ppm" "$tmp/imgs/b.ppm"
"$bin/headcast-track" --input "$tmp/imgs" --out "$tmp/y.hcrec" --json "$tmp/y.json" > /dev/null 2>&1
grep -q '"unreadable_frames": 1' "$tmp/y.json" && grep -q '"frames": 1' "$tmp/y.json" && ok "corrupt image is a status, the run completes" || bad "images: $(cat "$tmp/y.json" 2>/dev/null)"
mkdir "$tmp/empty"
out=$("$bin/headcast-track" --input "$tmp/empty" --out "$tmp/z.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "no images" <<<"$out" && ok "empty folder refused" || bad "empty: $out"
out=$("$bin/headcast-track" --input /dev/video97 --out "$tmp/c.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "no such device" <<<"$out" && ok "missing camera refused clearly" || bad "camera: $out"
out=$("$bin/headcast-track" --input zed:/dev/video97 --out "$tmp/c.hcrec" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "needs a calibration" <<<"$out" && ok "stereo without calibration refused" || bad "zed: $out"
checks_summary "track cli"
