#!/usr/bin/env bash
# headcast bandwidth measurement runs.
#
#   deploy/netlab/netlab.sh [--mode netns|loopback] [--rate KBIT] [--duration S] [--fps F]
#                           [--recording REC [--head-model M]] [--out DIR] [--min-send-interval S] [--max-batch N]
#                           [--max-kbps K] [--freshest] [--datagrams auto|on|off] [--queue-ms MS] [--pcap FILE]
#
# --recording replays a parameter recording (e.g. a real person tracked with
# ICT-FaceKit by headcast-track); --head-model is the model .npz it was made
# with (the receiver's avatar is made for that model). Default: the built-in
# head's synthetic talking sequence. --freshest: the sender's newest-frame-only
# mode (one frame per message, the receiver interpolates). --datagrams: the
# sender's choice of frames as UDP datagrams (default auto: under 32 kbit/s).
# --queue-ms: the tbf's queue in ms of the rate (default 1000); what does not
# fit is dropped, so a short queue and a budget above the rate make loss.
#
# netns (root): two network namespaces joined by a veth pair (the project's own
# test hosts, 10.213.0.1 receiver / 10.213.0.2 sender), optionally a tbf rate
# limit on the sender->receiver direction; TLS with certificates made for the
# run. The kernel's byte and packet counters of the sender's veth give what
# travels on the wire in each direction (Ethernet, IP, TCP, HTTP/2, gRPC and
# all). loopback: both on 127.0.0.1, plaintext; bytes per direction from the
# sender socket's TCP counters (ss), plus 52 bytes of IP+TCP headers per segment.
#
# Writes OUT/netlab.json (summary), OUT/timeline.csv (per second), OUT/latency.csv
# (per frame) and OUT/netlab.png (bitrate and latency over time); cleans up.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin=$root/build/bin
mode=netns rate=0 duration=30 fps=30 recording="" head_model=builtin out="" freshest=() pcap="" min_interval=0 max_batch=16 max_kbps="" datagrams=auto queue_ms=1000 python=/usr/bin/python3
while [ $# -gt 0 ]; do
  case $1 in
    --mode) mode=$2; shift 2 ;;
    --rate) rate=$2; shift 2 ;;
    --duration) duration=$2; shift 2 ;;
    --fps) fps=$2; shift 2 ;;
    --recording) recording=$2; shift 2 ;;
    --head-model) head_model=$2; shift 2 ;;
    --freshest) freshest=(--freshest); shift ;;
    --out) out=$2; shift 2 ;;
    --min-send-interval) min_interval=$2; shift 2 ;;
    --max-batch) max_batch=$2; shift 2 ;;
    --max-kbps) max_kbps=$2; shift 2 ;;
    --pcap) pcap=$2; shift 2 ;;
    --datagrams) datagrams=$2; shift 2 ;;
    --queue-ms) queue_ms=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/{/^#/p}' "$0"; exit 0 ;;
    *) echo "netlab: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -x "$python" ] || python=python3
[ -n "$out" ] || out=$root/out/netlab/${mode}_${rate}kbit
# The sender's link budget: 92 % of the rate limit unless given (its pacer counts every byte it causes).
[ -n "$max_kbps" ] || max_kbps=$(awk "BEGIN{print ($rate > 0) ? $rate * 0.92 : 0}")
mkdir -p "$out"
for b in headcast-sender headcast-receiver headcast-avatar; do
  [ -x "$bin/$b" ] || { echo "netlab: $bin/$b missing; run deploy/setup.sh" >&2; exit 1; }
done
work=$(mktemp -d)
rx=hc_netlab_rx_$$ tx=hc_netlab_tx_$$
cleanup() {
  [ -n "${rpid:-}" ] && kill "$rpid" 2>/dev/null || true
  [ -n "${spid:-}" ] && kill "$spid" 2>/dev/null || true
  [ -n "${dpid:-}" ] && kill "$dpid" 2>/dev/null || true
  wait 2>/dev/null || true
  if [ "$mode" = netns ]; then
    ip netns del "$rx" 2>/dev/null || true
    ip netns del "$tx" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT

[ "$head_model" = builtin ] || [ -f "$head_model" ] || { echo "netlab: no head model $head_model" >&2; exit 2; }
[ -z "$recording" ] || [ -f "$recording" ] || { echo "netlab: no recording $recording" >&2; exit 2; }
# The receiver's avatar (untrained: the link is measured, not the picture), of the recording's head model.
"$bin/headcast-avatar" create --head-model "$head_model" --resolution 128 --out "$work/avatar.hcavatar" > /dev/null
if [ -z "$recording" ]; then
  [ "$head_model" = builtin ] || { echo "netlab: --head-model needs the --recording made with it" >&2; exit 2; }
  recording=$work/talk.hcrec
  "$bin/headcast-avatar" synth-params --frames "$(awk "BEGIN{print int($fps*60)}")" --fps "$fps" --out "$recording" > /dev/null
fi
token=netlab-$$

if [ "$mode" = netns ]; then
  [ "$(id -u)" -eq 0 ] || { echo "netlab: netns mode needs root (ip netns); try --mode loopback" >&2; exit 1; }
  ip netns add "$rx"
  ip netns add "$tx"
  ip link add veth_rx_$$ netns "$rx" type veth peer name veth_tx_$$ netns "$tx"
  ip -n "$rx" addr add 10.213.0.1/24 dev veth_rx_$$
  ip -n "$tx" addr add 10.213.0.2/24 dev veth_tx_$$
  ip -n "$rx" link set veth_rx_$$ up
  ip -n "$tx" link set veth_tx_$$ up
  ip -n "$rx" link set lo up
  ip -n "$tx" link set lo up
  if [ "$rate" != 0 ]; then
    # Token bucket on the sender's egress: RATE kbit/s, one MTU of burst, 1 s of queue (--queue-ms).
    ip netns exec "$tx" tc qdisc add dev veth_tx_$$ root tbf rate "${rate}kbit" burst 1600 latency "${queue_ms}ms"
  fi
  "$root/deploy/make_certs.sh" "$work/certs" 10.213.0.1 > /dev/null
  run_rx=(ip netns exec "$rx")
  run_tx=(ip netns exec "$tx")
  listen=10.213.0.1:50051
  rx_tls=(--tls-cert "$work/certs/server.pem" --tls-key "$work/certs/server.key")
  tx_tls=(--tls-ca "$work/certs/ca.pem")
  counters() { ip netns exec "$tx" cat /sys/class/net/veth_tx_$$/statistics/{tx_bytes,rx_bytes,tx_packets,rx_packets} | tr '\n' ' '; }
else
  port=$((20000 + RANDOM % 20000))
  run_rx=() run_tx=()
  listen=127.0.0.1:$port
  rx_tls=(--plaintext)
  tx_tls=(--plaintext)
  # Sender socket: bytes it sent/received plus IP+TCP headers (20 + 32 with timestamps) per segment.
  counters() {
    ss -tinH state established "( dport = :$port )" 2>/dev/null | awk '
      { for (i = 1; i <= NF; i++) { split($i, kv, ":");
          if (kv[1] == "bytes_sent") bs = kv[2]; if (kv[1] == "bytes_received") br = kv[2];
          if (kv[1] == "segs_out") so = kv[2]; if (kv[1] == "segs_in") si = kv[2]; } }
      END { printf "%d %d %d %d", bs + 52 * so, br + 52 * si, so, si }'
  }
fi

"${run_rx[@]}" "$bin/headcast-receiver" --listen "$listen" "${rx_tls[@]}" --token "$token" --head-model "$head_model" --avatar demo="$work/avatar.hcavatar" \
  --display none --render-fps "$fps" --duration "$(awk "BEGIN{print $duration + 15}")" --latency-csv "$out/latency.csv" \
  --json "$out/receiver.json" > /dev/null 2> "$work/receiver.log" &
rpid=$!
for _ in $(seq 100); do grep -q listening "$work/receiver.log" && break; sleep 0.1; done
grep -q listening "$work/receiver.log" || { cat "$work/receiver.log"; exit 1; }
if [ -n "$pcap" ]; then
  # Packet capture on the sender's side of the link, for looking at per-message overheads.
  command -v tcpdump > /dev/null || { echo "netlab: --pcap needs tcpdump (apt-get install tcpdump)" >&2; exit 1; }
  if [ "$mode" = netns ]; then dev=veth_tx_$$; else dev=lo; fi
  "${run_tx[@]}" tcpdump -i "$dev" -s 200 -w "$pcap" tcp or udp 2> /dev/null &
  dpid=$!
  sleep 0.5
fi
"${run_tx[@]}" "$bin/headcast-sender" --target "$listen" "${tx_tls[@]}" --token "$token" --avatar-id demo \
  --head-model "$head_model" --params "$recording" --loop --duration "$duration" --min-send-interval "$min_interval" --max-batch "$max_batch" \
  --max-kbps "$max_kbps" "${freshest[@]}" --datagrams "$datagrams" \
  --json "$out/sender.json" > /dev/null 2> "$work/sender.log" &
spid=$!
echo "t,up_bytes,down_bytes,up_packets,down_packets" > "$out/timeline.csv"
start=$(date +%s.%N)
while kill -0 "$spid" 2>/dev/null; do
  now=$(date +%s.%N)
  read -r ub db up dp <<< "$(counters)"
  echo "$(awk "BEGIN{printf \"%.2f\", $now - $start}"),${ub:-0},${db:-0},${up:-0},${dp:-0}" >> "$out/timeline.csv"
  sleep 1
done
wait "$spid" || { echo "netlab: sender failed"; cat "$work/sender.log"; exit 1; }
spid=
kill "$rpid" 2>/dev/null || true
wait "$rpid" 2>/dev/null || true
rpid=
if [ -n "${dpid:-}" ]; then kill "$dpid" 2>/dev/null || true; wait "$dpid" 2>/dev/null || true; dpid=; fi
"$python" "$root/deploy/netlab/analyse.py" --dir "$out" --mode "$mode" --rate "$rate" --fps "$fps" --duration "$duration"
