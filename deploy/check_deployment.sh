#!/usr/bin/env bash
# Checks the deployment files on a fresh Debian 12, with Docker:
#   1. builds the image from deploy/Dockerfile (a clean clone of HEAD, so
#      nothing from this checkout's build/ or out/ leaks in);
#   2. runs deploy/demo.sh inside it, as a newcomer would (offscreen), and
#      copies its outputs to OUT/demo;
#   3. boots a container with systemd as PID 1, installs the receiver exactly as
#      deploy/systemd/headcast-receiver.service says (system user, the example
#      config, certificates from deploy/make_certs.sh, a token), starts the
#      unit, and drives it with a sender over TLS with the token on loopback;
#   4. builds the runtime stage (the package alone, a user of its own), prints
#      both images' sizes, runs the receiver in it with certificates and waits
#      for Docker's health check (gRPC health over TLS) to say healthy.
#
#   deploy/check_deployment.sh OUT [BASE_IMAGE]
#
# BASE_IMAGE defaults to debian:12. HEADCAST_CHECK_IMAGE=TAG skips the build and
# checks an image built from deploy/Dockerfile before. Without a registry, make it from Debian's
# archive:  debootstrap --variant=minbase bookworm ROOT && tar -C ROOT -c . | docker import - debian:12
# The container uses the host's network (loopback only): port 50051 must be free.
set -euo pipefail
out=$(mkdir -p "${1:?usage: check_deployment.sh OUT [BASE_IMAGE]}" && cd "$1" && pwd)
base=${2:-debian:12}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
say() { echo "check_deployment: $*" >&2; }

clone=$(mktemp -d)
trap 'rm -rf "$clone"; docker rm -f headcast-systemd-check >/dev/null 2>&1 || true' EXIT
git clone -q "$root" "$clone/headcast"
[ "$base" = debian:12 ] || sed -i "s|^FROM debian:12 |FROM $base |" "$clone/headcast/deploy/Dockerfile"

if [ -n "${HEADCAST_CHECK_IMAGE:-}" ]; then  # an image built from this Dockerfile before: steps 2 and 3 only
  docker tag "$HEADCAST_CHECK_IMAGE" headcast:check
else
  say "1. docker build --target build (Debian 12, setup.sh installs and builds everything)"
  start=$(date +%s)
  docker build --network host -f "$clone/headcast/deploy/Dockerfile" --target build -t headcast:check "$clone/headcast" \
    > "$out/docker_build.log" 2>&1 || { tail -20 "$out/docker_build.log" >&2; exit 1; }
  say "   built in $(($(date +%s) - start)) s (log: $out/docker_build.log)"
fi

say "2. deploy/demo.sh inside the image"
docker run --rm --network host -v "$out:/check" --entrypoint bash headcast:check -c \
  'deploy/demo.sh --out /check/demo' > "$out/demo.log" 2>&1 || { tail -20 "$out/demo.log" >&2; exit 1; }
tail -12 "$out/demo.log" >&2

say "3. the receiver as a systemd service"
docker build --network host -t headcast:check-systemd - > "$out/systemd_image.log" 2>&1 <<'EOF' ||
FROM headcast:check
RUN apt-get update && apt-get install -y --no-install-recommends systemd systemd-sysv && rm -rf /var/lib/apt/lists/*
ENTRYPOINT ["/lib/systemd/systemd"]
EOF
  { tail -20 "$out/systemd_image.log" >&2; exit 1; }
docker run -d --name headcast-systemd-check --cgroupns=host -v /sys/fs/cgroup:/sys/fs/cgroup:rw \
  --network host --tmpfs /run --tmpfs /run/lock headcast:check-systemd > /dev/null
in_box() { docker exec headcast-systemd-check bash -c "$1"; }
for _ in $(seq 30); do in_box 'systemctl is-system-running 2>/dev/null | grep -qE "running|degraded"' && break; sleep 1; done
# The unit file's own install steps, as its comments give them (certificates and a token included).
in_box 'set -e; cd /opt/headcast
  cmake --install build --prefix /usr > /dev/null
  useradd --system --home /var/lib/headcast --shell /usr/sbin/nologin headcast
  install -d -o headcast -g headcast -m 0750 /etc/headcast /var/lib/headcast
  cp /usr/share/headcast/examples/receiver.toml /etc/headcast/receiver.toml
  deploy/make_certs.sh /etc/headcast/certs localhost 127.0.0.1 > /dev/null
  (umask 077; openssl rand -hex 16 > /etc/headcast/tokens.txt)
  chown -R headcast:headcast /etc/headcast
  systemctl daemon-reload && systemctl enable --now headcast-receiver' > "$out/systemd.log" 2>&1
sleep 3
in_box 'systemctl is-active headcast-receiver' >> "$out/systemd.log" 2>&1 || {
  in_box 'journalctl -u headcast-receiver --no-pager | tail -20' >&2; exit 1; }
in_box 'cd /opt/headcast && build/bin/headcast-sender --target localhost:50051 --tls-ca /etc/headcast/certs/ca.pem \
  --token-file /etc/headcast/tokens.txt --avatar-id demo --synthetic 90 --json /tmp/sender.json' >> "$out/systemd.log" 2>&1
in_box 'systemd-analyze security headcast-receiver | tail -1' >> "$out/systemd.log" 2>&1 || true
in_box 'systemctl stop headcast-receiver; cat /var/lib/headcast/receiver_stats.json' > "$out/receiver_stats.json"
in_box 'journalctl -u headcast-receiver --no-pager' > "$out/journal.log" 2>&1 || true
in_box 'cat /tmp/sender.json' > "$out/sender.json"
python3 - "$out" <<'EOF'
import json, sys
out = sys.argv[1]
rx = json.load(open(out + "/receiver_stats.json"))
tx = json.load(open(out + "/sender.json"))
print(f"check_deployment: the service took {rx['sessions_started']} TLS session(s) with the token, received "
      f"{rx['frames_received']} of the {tx['frames_sent']} frames sent ({rx['frames_bad']} bad), rendered {rx['rendered']}",
      file=sys.stderr)
sys.exit(0 if rx["sessions_started"] >= 1 and rx["frames_received"] == tx["frames_sent"] > 0 and rx["rendered"] > 0 else 1)
EOF

say "4. the runtime image: size and health"
docker build --network host -f "$clone/headcast/deploy/Dockerfile" -t headcast:check-runtime "$clone/headcast" \
  > "$out/runtime_build.log" 2>&1 || { tail -20 "$out/runtime_build.log" >&2; exit 1; }
size() { echo $(($(docker image inspect -f '{{.Size}}' "$1") / 1048576)); }
say "   build stage $(size headcast:check) MB, runtime image $(size headcast:check-runtime) MB"
mkdir -p "$out/runtime_certs"
"$root/deploy/make_certs.sh" "$out/runtime_certs" localhost 127.0.0.1 > /dev/null
(umask 077; openssl rand -hex 16 > "$out/runtime_certs/tokens.txt")
chmod -R a+rX "$out/runtime_certs"
docker rm -f headcast-runtime-check > /dev/null 2>&1 || true
docker run -d --name headcast-runtime-check --network host -v "$out/runtime_certs:/certs:ro" headcast:check-runtime \
  --listen 127.0.0.1:50051 --tls-cert /certs/server.pem --tls-key /certs/server.key --token-file /certs/tokens.txt \
  --avatar demo=/usr/share/headcast/models/demo_avatar.hcavatar --display none > /dev/null
health=starting
for _ in $(seq 60); do
  health=$(docker inspect -f '{{.State.Health.Status}}' headcast-runtime-check)
  [ "$health" = starting ] || break
  sleep 2
done
user=$(docker exec headcast-runtime-check id -un)
docker rm -f headcast-runtime-check > /dev/null
say "   health: $health, running as $user"
[ "$health" = healthy ] && [ "$user" = headcast ] || exit 1
say "done: $out (docker_build.log, demo/, demo.log, systemd.log, journal.log, receiver_stats.json, sender.json, runtime_build.log)"
