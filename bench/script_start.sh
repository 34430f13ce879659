# Sourced first (without arguments) by the bench scripts whose first argument is
# OUT, their work folder: where the project, python, the shared data and the
# binaries are; the script's opening comment as its usage when called without
# arguments; `out` taken off the arguments; and `command`, the call as the
# results record it (OUT and the flags: no machine paths). A script whose OUT
# is another run's folder names it in `out_name` before sourcing.
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${HEADCAST_PYTHON:-/usr/bin/python3}
data=${HEADCAST_DATA:-$root/../shared/data}
bin=${HEADCAST_BIN:-$root/build/bin}
[ $# -ge 1 ] || { sed -n '2,/^[^#]/{/^#/p}' "$0" >&2; exit 2; }
out=$1; shift
command="bench/$(basename "$0") ${out_name:-OUT} $*"
