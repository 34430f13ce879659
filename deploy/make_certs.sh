#!/usr/bin/env bash
# Makes a private CA and, signed by it, a receiver (server) certificate and a
# sender (client) certificate for headcast's TLS.
#
#   deploy/make_certs.sh OUT_DIR [SERVER_NAME ...]
#
# SERVER_NAMEs (DNS names or IP addresses the receiver is reached by) default to
# "localhost 127.0.0.1". Writes ca.pem/ca.key, server.pem/server.key,
# client.pem/client.key into OUT_DIR (keys readable by the owner only). Run
# again on the same OUT_DIR (to add a server name, say), it keeps the CA, so
# whoever trusts it still does, and issues new server and client certificates.
# Receiver: --tls-cert server.pem --tls-key server.key [--tls-client-ca ca.pem]
# Sender:   --tls-ca ca.pem [--tls-cert client.pem --tls-key client.key]
set -euo pipefail
out=${1:?usage: make_certs.sh OUT_DIR [SERVER_NAME ...]}
shift
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(localhost 127.0.0.1)
mkdir -p "$out"
cd "$out"
umask 077
san=""
for n in "${names[@]}"; do
  if [[ $n =~ ^[0-9.]+$ || $n == *:* ]]; then san+="IP:$n,"; else san+="DNS:$n,"; fi
done
san=${san%,}
days=825
if [ -f ca.pem ] && [ -f ca.key ]; then
  echo "make_certs: keeping the CA in $out; new server and client certificates" >&2
else
  openssl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.pem -days "$days" -subj "/CN=headcast private CA" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
fi
issue() {  # name, subject CN, extended key usage, SAN (optional)
  local name=$1 cn=$2 eku=$3 alt=${4:-}
  openssl req -newkey rsa:2048 -nodes -keyout "$name.key" -out "$name.csr" -subj "/CN=$cn" 2>/dev/null
  {
    echo "basicConstraints=CA:FALSE"
    echo "keyUsage=critical,digitalSignature,keyEncipherment"
    echo "extendedKeyUsage=$eku"
    [ -n "$alt" ] && echo "subjectAltName=$alt"
  } > "$name.ext"
  openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -out "$name.pem" -days "$days" \
    -extfile "$name.ext" 2>/dev/null
  rm -f "$name.csr" "$name.ext"
}
issue server "${names[0]}" serverAuth "$san"
issue client "headcast sender" clientAuth
rm -f ca.srl
echo "headcast certificates in $out: ca.pem, server.pem/.key (${names[*]}), client.pem/.key"
