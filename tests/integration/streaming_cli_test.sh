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
"$bin/headcast-avatar" create --resolution 128 --out "$tmp/demo.hcavatar" > /dev/null
echo "s3cret" > "$tmp/tokens.txt"
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
token = "s3cret"
avatar-id = "demo"
synthetic = 60
record = "$tmp/sent.hcrec"
# Every frame must arrive: a loaded machine takes long over the TLS handshake,
# and the product's 16-frame queue would drop the first frames meanwhile.
queue = 120
TOML
"$bin/headcast-sender" --config "$tmp/sender.toml" > "$tmp/sender.json" 2> "$tmp/sender.log" \
  && grep -q '"frames_sent": 60' "$tmp/sender.json" && ok "sender streams 60 frames over TLS (config file)" || bad "sender: $(cat "$tmp/sender.log")"
out=$("$bin/headcast-sender" --config "$tmp/sender.toml" --token wrong --synthetic 5 2>&1); rc=$?
[ $rc -eq 2 ] && grep -q "UNAUTHENTICATED: wrong bearer token" <<<"$out" && ok "wrong token refused with the reason" || bad "wrong token: $out"
out=$("$bin/headcast-sender" --target "10.1.2.3:$port" --plaintext --token s3cret 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "plaintext is only allowed" <<<"$out" && ok "plaintext off loopback refused" || bad "plaintext: $out"
out=$("$bin/headcast-sender" --config "$tmp/sender.toml" --avatar-id nobody --synthetic 5 2>&1); rc=$?
[ $rc -eq 2 ] && grep -q "UNKNOWN_AVATAR" <<<"$out" && ok "unknown avatar refused" || bad "avatar: $out"
# SIGTERM rather than a short duration: under load the checks above may take
# longer than any fixed window, and the receiver writes its stats on SIGTERM too.
kill -TERM "$rpid"; wait "$rpid"; rpid=
grep -q '"frames_received": 60' "$tmp/receiver.json" && ok "receiver got 60 frames" || bad "receiver: $(cat "$tmp/receiver.json")"
sent=$("$bin/headcast-avatar" render "$tmp/demo.hcavatar" --params "$tmp/received.hcrec" --display none --unpaced --stats-json "$tmp/r.json" > /dev/null 2>&1; grep -o '"rendered": [0-9]*' "$tmp/r.json")
[ "$sent" = '"rendered": 60' ] && ok "the receiver's recording replays (60 frames)" || bad "replay: $sent"
checks_summary "streaming cli"
