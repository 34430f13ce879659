#!/usr/bin/env bash
# Builds the frame-decoder fuzzer with clang (libFuzzer + ASan + UBSan) and runs it.
#   tests/fuzz/run_fuzz.sh SECONDS [BUILD_DIR]
# Prints libFuzzer's summary, including the number of executions.
set -euo pipefail
seconds=${1:-60}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
out=${2:-$root/build/fuzz}
mkdir -p "$out/corpus"
bin=$out/frame_decoder_fuzzer
srcs=(tests/fuzz/frame_decoder_fuzzer.cc common/codec/param_codec.cc common/codec/bit_stream.cc
      common/core/options.cc common/core/rotation.cc common/core/camera.cc common/headmodel/head_model.cc
      common/headmodel/params.cc)
newest=$(cd "$root" && ls -t "${srcs[@]}" | head -1)
if [ ! -x "$bin" ] || [ "$root/$newest" -nt "$bin" ]; then
  (cd "$root" && clang++ -std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
     -I . -isystem /usr/include/eigen3 "${srcs[@]}" -o "$bin")
fi
# Seed corpus: a few well-formed packets would be nice; libFuzzer finds them quickly anyway.
"$bin" -max_total_time="$seconds" -max_len=512 -print_final_stats=1 "$out/corpus" 2>&1 | tail -n 25
