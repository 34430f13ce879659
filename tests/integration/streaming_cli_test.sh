#!/usr/bin/env bash
# headcast-receiver and headcast-sender as a user runs them: config files, TLS
# with certificates from deploy/make_certs.sh, recordings at both ends, refusals.
set -u
bin=$1; src=$2
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
port=$((20000 + RANDOM % 20000))
cleanup() { [ -n "${rpid:-}" ] && kill "$rpid" 2>/dev/null; wait 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT
"$src/deploy/make_certs.sh" "$tmp/certs" > /dev/null
cp "$tmp/certs/ca.pem" "$tmp/ca_first.pem"
"$src/deploy/make_certs.sh" "$tmp/certs" localhost 127.0.0.1 > /dev/null 2>&1
cmp -s "$tmp/certs/ca.pem" "$tmp/ca_first.pem" && openssl verify -CAfile "$tmp/ca_first.pem" "$tmp/certs/server.pem" > /dev/null &&
  ok "make_certs.sh run again keeps the CA" || bad "make_certs.sh replaced the CA"
"$bin/headcast-avatar" create --resolution 128 --out "$tmp/demo.hcavatar" > /dev/null
token=0123456789abcdef0123
# Windows line endings, a comment and blank lines: only the token counts.
printf '# receiver tokens\r\n\r\n%s\r\n' "$token" > "$tmp/tokens.txt"
cat > "$tmp/receiver.toml" <<TOML
listen = "127.0.0.1:$port"
tls-cert = "$tmp/certs/server.pem"
tls-key = "$tmp/certs/server.key"
token-file = "$tmp/tokens.txt"
avatar = ["demo=$tmp/demo.hcavatar"]
display = "none"
duration = 120
record = "$tmp/received.hcrec"
stats-json = "$tmp/receiver.json"
TOML
"$bin/headcast-receiver" --config "$tmp/receiver.toml" > /dev/null 2> "$tmp/receiver.log" &
rpid=$!
wait_for "$tmp/receiver.log" listening || bad "receiver never listened"
cat > "$tmp/sender.toml" <<TOML
target = "localhost:$port"
tls-ca = "$tmp/certs/ca.pem"
token-file = "$tmp/sender_token.txt"
avatar-id = "demo"
synthetic = 60
record = "$tmp/sent.hcrec"
# Every frame must arrive: a loaded machine takes long over the TLS handshake,
# and the product's 16-frame queue would drop the first frames meanwhile.
queue = 120
TOML
printf '%s\r\n' "$token" > "$tmp/sender_token.txt"
"$bin/headcast-sender" --config "$tmp/sender.toml" > "$tmp/sender.json" 2> "$tmp/sender.log" \
  && grep -q '"frames_sent": 60' "$tmp/sender.json" && ok "sender streams 60 frames over TLS (config file)" || bad "sender: $(cat "$tmp/sender.log")"
printf 'wrong-token-0123456789\n' > "$tmp/wrong_token.txt"
sed 's/sender_token.txt/wrong_token.txt/' "$tmp/sender.toml" > "$tmp/wrong.toml"
# --loop would stream forever: a refusal that cannot heal must end the sender at once.
out=$(timeout 30 "$bin/headcast-sender" --config "$tmp/wrong.toml" --synthetic 5 --loop 2>&1); rc=$?
[ $rc -eq 2 ] && grep -q "UNAUTHENTICATED: wrong bearer token" <<<"$out" && [ "$(grep -c 'retrying in' <<<"$out")" -eq 0 ] \
  && ok "wrong token refused with the reason, not retried" || bad "wrong token (rc $rc): $out"
out=$("$bin/headcast-sender" --config "$tmp/sender.toml" --token "$token" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "excludes" <<<"$out" && ok "--token and --token-file exclude each other" || bad "token twice: $out"
out=$("$bin/headcast-sender" --target "10.1.2.3:$port" --plaintext --token "$token" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "plaintext is only allowed" <<<"$out" && ok "plaintext off loopback refused" || bad "plaintext: $out"
out=$("$bin/headcast-sender" --config "$tmp/sender.toml" --avatar-id nobody --synthetic 5 2>&1); rc=$?
[ $rc -eq 2 ] && grep -q "UNKNOWN_AVATAR" <<<"$out" && ok "unknown avatar refused" || bad "avatar: $out"
out=$("$bin/headcast-sender" --config "$tmp/sender.toml" --expression-components 100000 --synthetic 5 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "expression component 100000 is outside" <<<"$out" && ok "out-of-range component refused" \
  || bad "components (rc $rc): $out"
out=$("$bin/headcast-sender" --config "$tmp/sender.toml" --tls-ca "$tmp/no-such-ca.pem" --synthetic 5 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "cannot read $tmp/no-such-ca.pem" <<<"$out" && ok "missing CA file refused before connecting" \
  || bad "tls-ca (rc $rc): $out"
# A second receiver on the same port must not start (and steal half the senders).
out=$(timeout 30 "$bin/headcast-receiver" --config "$tmp/receiver.toml" --record "" --stats-json "" 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "cannot listen" <<<"$out" && ok "a busy port is refused" || bad "second receiver (rc $rc): $out"
for listen in 127.0.0.1 127.0.0.1:99999; do
  out=$("$bin/headcast-receiver" --listen "$listen" --plaintext --token "$token" --avatar demo="$tmp/demo.hcavatar" \
    --display none --duration 1 2>&1); rc=$?
  [ $rc -eq 1 ] && grep -q "is not host:port" <<<"$out" && ok "--listen $listen refused" || bad "--listen $listen (rc $rc): $out"
done
# A misspelt key (underscores) must not be dropped: here it would turn mutual TLS off.
sed "s|^display|tls_client_ca = \"$tmp/certs/ca.pem\"\ndisplay|" "$tmp/receiver.toml" > "$tmp/typo.toml"
out=$(timeout 30 "$bin/headcast-receiver" --config "$tmp/typo.toml" --listen 127.0.0.1:0 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "tls_client_ca" <<<"$out" && ok "a misspelt config key is refused by name" || bad "typo (rc $rc): $out"
printf '[server]\nlisten = "127.0.0.1:0"\n' > "$tmp/section.toml"
out=$(timeout 30 "$bin/headcast-receiver" --config "$tmp/section.toml" --token "$token" --avatar demo="$tmp/demo.hcavatar" 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "server" <<<"$out" && ok "an unknown config section is refused" || bad "section (rc $rc): $out"
# Under systemd (Type=notify, WatchdogSec): READY=1 once listening, then watchdog pings.
got=$(python3 - "$bin/headcast-receiver" "$tmp" "$token" <<'PY'
import os, socket, subprocess, sys, time
exe, tmp, token = sys.argv[1:4]
path = os.path.join(tmp, "notify.sock")
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
s.bind(path)
s.settimeout(1)
env = dict(os.environ, NOTIFY_SOCKET=path, WATCHDOG_USEC="1000000")
p = subprocess.Popen([exe, "--listen", "127.0.0.1:0", "--plaintext", "--token", token, "--avatar",
                      "demo=" + os.path.join(tmp, "demo.hcavatar"), "--display", "none", "--duration", "30"],
                     env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
seen, end = [], time.time() + 20
while time.time() < end and seen.count("WATCHDOG=1") < 2:
    try:
        seen.append(s.recv(256).decode())
    except socket.timeout:
        pass
p.terminate()
p.wait()
print(" ".join(seen))
PY
)
[[ $got == READY=1*WATCHDOG=1*WATCHDOG=1* ]] && ok "systemd: ready, then watchdog pings" || bad "notify: '$got'"
printf 'short\n' > "$tmp/short_tokens.txt"
out=$("$bin/headcast-receiver" --listen 127.0.0.1:0 --plaintext --token-file "$tmp/short_tokens.txt" --avatar demo="$tmp/demo.hcavatar" \
  --display none --duration 1 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "short_tokens.txt: line 1: a token needs at least 16" <<<"$out" && ok "a short token is refused" \
  || bad "short token (rc $rc): $out"
# The health probe, over TLS as a session would connect: serving now, unreachable once it is gone.
health=$("$bin/headcast-sender" --target "localhost:$port" --tls-ca "$tmp/certs/ca.pem" --health-check 10 2>&1)
[ $? -eq 0 ] && [ "$health" = SERVING ] && ok "--health-check: the receiver is SERVING (gRPC health over TLS)" ||
  bad "health check: $health"
# SIGTERM rather than a short duration: under load the checks above may take
# longer than any fixed window, and the receiver writes its stats on SIGTERM too.
kill -TERM "$rpid"; wait "$rpid"; rpid=
health=$("$bin/headcast-sender" --target "localhost:$port" --tls-ca "$tmp/certs/ca.pem" --health-check 1 2>&1)
[ $? -eq 1 ] && grep -q "^unreachable" <<<"$health" && ok "--health-check fails (exit 1) when no receiver answers" ||
  bad "health check of a stopped receiver: $health"
grep -q '"frames_received": 60' "$tmp/receiver.json" && ok "receiver got 60 frames" || bad "receiver: $(cat "$tmp/receiver.json")"
sent=$("$bin/headcast-avatar" render "$tmp/demo.hcavatar" --params "$tmp/received.hcrec" --display none --pacing none --json "$tmp/r.json" > /dev/null 2>&1; grep -o '"rendered": [0-9]*' "$tmp/r.json")
[ "$sent" = '"rendered": 60' ] && ok "the receiver's recording replays (60 frames)" || bad "replay: $sent"
checks_summary "streaming cli"
