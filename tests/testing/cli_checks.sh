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
# wait_for FILE PATTERN: until FILE holds PATTERN, up to 60 s (a loaded machine
# starts a server slowly; a short fixed wait made the tests flaky). Fails if never.
wait_for() {
  local i
  for i in $(seq 600); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.1; done
  echo "no '$2' in $1 after 60 s: $(tail -5 "$1" 2>/dev/null)"
  return 1
}
