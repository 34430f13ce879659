#!/usr/bin/env bash
# No committed file names a path of the machine it was made on: reports,
# READMEs, JSON results and the manifests of shipped avatars must read the
# same on every clone. Absolute paths under /work, /root and /home are the
# tell (a path of a build or a session, never of an installed program).
# usage: machine_paths_check.sh ROOT [PYTHON]
set -uo pipefail
root=$1
python=${2:-/usr/bin/python3}
cd "$root" || exit 1
pattern='(^|[[:space:]"'"'"'=(:,`])/(work|root|home)/'
bad=0
while IFS= read -r -d '' f; do
  case $f in *.png | *.jpg | *.mp4 | *.npz | *.hcavatar | *.pt | *.dat) continue ;; esac
  if grep -InE "$pattern" -- "$f" > /tmp/machine_paths.$$ 2>/dev/null; then
    sed "s|^|$f:|" /tmp/machine_paths.$$
    bad=1
  fi
done < <(git ls-files -z)
rm -f /tmp/machine_paths.$$
# Shipped avatars: their manifests (training summaries name their inputs).
for f in $(git ls-files '*.hcavatar'); do
  "$python" - "$f" <<'PY' || bad=1
import re, sys, zipfile
text = zipfile.ZipFile(sys.argv[1]).read("manifest.json").decode()
hits = re.findall(r'"(/(?:work|root|home|tmp)/[^"]*)"', text)
for h in hits:
    print(f"{sys.argv[1]}: manifest names {h}")
sys.exit(1 if hits else 0)
PY
done
[ "$bad" = 0 ] && echo "machine paths: none in $(git ls-files | wc -l) committed files"
exit "$bad"
