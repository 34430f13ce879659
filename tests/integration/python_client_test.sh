#!/usr/bin/env bash
# The Python third-party client streams a recording to the real receiver over
# gRPC on 127.0.0.1; the receiver's own recording of what it got must match.
set -u
bin=$1; python=$2; src=$3
source "$(dirname "${BASH_SOURCE[0]}")/../testing/cli_checks.sh"
port=$((20000 + RANDOM % 20000))
cleanup() { [ -n "${rpid:-}" ] && kill "$rpid" 2>/dev/null; wait 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT
"$bin/headcast-avatar" create --resolution 128 --out "$tmp/a.hcavatar" > /dev/null
"$bin/headcast-avatar" synth-params --frames 45 --out "$tmp/talk.hcrec" > /dev/null
"$bin/headcast-receiver" --plaintext --listen "127.0.0.1:$port" --token pytoken --avatar demo="$tmp/a.hcavatar" \
  --display none --record "$tmp/received.hcrec" --duration 120 > "$tmp/receiver.json" 2> "$tmp/receiver.log" &
rpid=$!
wait_for "$tmp/receiver.log" listening || exit 1
"$python" "$src/tests/integration/python_client.py" --proto-dir "$src/proto" --target "127.0.0.1:$port" \
  --token pytoken --avatar-id demo --recording "$tmp/talk.hcrec" > "$tmp/client.json" || { cat "$tmp/client.json" "$tmp/receiver.log"; exit 1; }
kill -TERM "$rpid"; wait "$rpid"; rpid=  # SIGTERM: no fixed window to race under load
cat "$tmp/client.json"
# Compare what the receiver recorded with what was sent (within the client's steps).
"$python" - "$tmp/talk.hcrec" "$tmp/received.hcrec" "$src/proto" <<'PY'
import subprocess, sys, tempfile
gen = tempfile.mkdtemp()
subprocess.run(["protoc", f"--python_out={gen}", "-I", sys.argv[3], "headcast.proto"], check=True)
sys.path.insert(0, gen)
import headcast_pb2 as pb
def read(path):
    data = open(path, "rb").read(); pos = 8
    def varint():
        nonlocal pos
        shift = value = 0
        while True:
            b = data[pos]; pos += 1; value |= (b & 0x7F) << shift
            if not b & 0x80: return value
            shift += 7
    n = varint(); pos += n; frames = []
    while pos < len(data):
        n = varint(); frames.append(pb.FrameParams.FromString(data[pos:pos + n])); pos += n
    return frames
sent, got = read(sys.argv[1]), read(sys.argv[2])
assert len(got) == len(sent), f"received {len(got)} of {len(sent)} frames"
for a, b in zip(sent, got):
    assert a.sequence == b.sequence
    assert max(abs(x - y) for x, y in zip(a.expression, b.expression)) <= 0.005 + 1e-6
    assert max(abs(x - y) for x, y in zip(a.cam_translation, b.cam_translation)) <= 0.0001 + 1e-7
print(f"python client: {len(got)} frames received in order, within the quantisation step")
PY
