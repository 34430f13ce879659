#!/usr/bin/env bash
# Builds headcast's libFuzzer targets with clang (ASan + UBSan) and runs each.
#   tests/fuzz/run_fuzz.sh SECONDS [OUT_DIR] [TARGET...]
# Targets: frame_decoder (a Frames payload's packets), session_messages
# (Uplink messages: Hello and its layout, Frames; the bytes as a datagram), files (npy, npz/zip,
# .hcrec, token files, avatar manifests with their tracking anchor, config files). Default: all, each for
# SECONDS. Prints each target's executions, and fails if any crashed.
set -euo pipefail
seconds=${1:-60}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
out=${2:-$root/build/fuzz}
shift $(( $# >= 2 ? 2 : $# ))
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(frame_decoder session_messages files)
mkdir -p "$out/gen"
cd "$root"
# The messages' code, generated here so the fuzzers need no CMake build.
[ "$out/gen/proto/headcast.pb.cc" -nt proto/headcast.proto ] ||
  { mkdir -p "$out/gen/proto" && protoc --cpp_out="$out/gen/proto" -I proto headcast.proto; }
codec=(common/codec/param_codec.cc common/codec/range_coder.cc common/codec/varint.cc common/core/options.cc common/core/rotation.cc
       common/core/camera.cc common/headmodel/head_model.cc common/headmodel/params.cc common/headmodel/head_outline.cc)
proto=("$out/gen/proto/headcast.pb.cc" proto/convert.cc)
declare -A sources libs
sources[frame_decoder]="tests/fuzz/frame_decoder_fuzzer.cc ${codec[*]}"
libs[frame_decoder]="-lopencv_core"
sources[session_messages]="tests/fuzz/session_messages_fuzzer.cc ${codec[*]} ${proto[*]} proto/datagram.cc"
libs[session_messages]="-lprotobuf -lcrypto -lopencv_core"
sources[files]="tests/fuzz/files_fuzzer.cc ${codec[*]} ${proto[*]} proto/recording.cc proto/protocol.cc
  common/core/npy.cc common/core/zip_archive.cc common/core/check.cc common/core/log.cc
  common/avatar/avatar_config.cc common/avatar/matte.cc common/tracking/anchor_reference.cc
  common/tracking/expression_fit.cc"
libs[files]="-lprotobuf -lzip -lz -lspdlog -lfmt -lopencv_core -lopencv_imgproc"
failed=0
for t in "${targets[@]}"; do
  [ -n "${sources[$t]:-}" ] || { echo "run_fuzz: no target $t" >&2; exit 2; }
  bin=$out/${t}_fuzzer
  # shellcheck disable=SC2086  # the lists are words
  newest=$(ls -t ${sources[$t]} | head -1)
  if [ ! -x "$bin" ] || [ "$newest" -nt "$bin" ]; then
    # shellcheck disable=SC2086
    clang++ -std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
      -DSPDLOG_FMT_EXTERNAL -I . -I "$out/gen" -isystem /usr/include/eigen3 -isystem /usr/include/opencv4 \
      ${sources[$t]} ${libs[$t]:-} -o "$bin"
  fi
  mkdir -p "$out/corpus_$t"
  # Seeds (well-formed inputs the mutations start from), where the target has them.
  [ -d "tests/fuzz/seeds/$t" ] && cp -n tests/fuzz/seeds/"$t"/* "$out/corpus_$t/"
  echo "== $t ($seconds s)"
  # -rss_limit_mb: what a file merely claims must not be allocated.
  if ! "$bin" -max_total_time="$seconds" -max_len=4096 -rss_limit_mb=1024 -timeout=10 -print_final_stats=1 \
      "$out/corpus_$t" > "$out/$t.log" 2>&1; then
    failed=1
    tail -n 40 "$out/$t.log"
  fi
  grep -E "stat::number_of_executed_units|stat::peak_rss_mb|Done [0-9]+ runs" "$out/$t.log" || true
done
exit $failed
