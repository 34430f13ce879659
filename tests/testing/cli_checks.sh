# Shared by the command-line tests: a scratch folder and ok/bad counters.
# Source it, call checks_summary NAME at the end (its status is the test's).
tmp=$(mktemp -d)
pass=0 fail=0
ok() { echo "ok   $1"; pass=$((pass + 1)); }
bad() { echo "FAIL $1"; fail=$((fail + 1)); }
checks_summary() {
  echo "$1 checks: $pass ok, $fail failing"
  [ "$fail" -eq 0 ]
}
