#!/usr/bin/env bash
# Installs every Debian package headcast needs, then configures and builds it.
# Idempotent: a second run only re-checks packages and rebuilds what changed.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_type=${HEADCAST_BUILD_TYPE:-Release}

packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config git clang-format
  # math, fitting, nearest neighbours
  libeigen3-dev libceres-dev
  # neural networks on the CPU; OpenBLAS makes libtorch's matrix products ~12x faster
  libtorch-dev libopenblas0-pthread libopenblas-dev
  # c10d's Gloo headers: data-parallel training (headcast-train --world-size)
  libgloo-dev
  # images, video, faces
  libopencv-dev libopencv-contrib-dev libdlib-dev libdlib-data ffmpeg
  # the stereo test pair (aloe) for the depth check
  opencv-doc
  # networking
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler libssl-dev
  # display: real window and headless rendering (libopengl-dev: CMake's OpenGL::OpenGL target)
  libglfw3-dev libosmesa6-dev libgl-dev libopengl-dev libglvnd-dev xvfb xauth
  # utilities
  libspdlog-dev libfmt-dev nlohmann-json3-dev libcli11-dev libzip-dev zlib1g-dev libjemalloc-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # converters, the Python test client, plots
  python3 python3-numpy python3-scipy python3-grpcio python3-protobuf python3-matplotlib
  # fuzzing (libFuzzer ships with clang's runtime), TLS certificates, network lab
  clang libclang-rt-14-dev openssl iproute2 tcpdump
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "headcast setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
  sudo_cmd=()
  [ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get update
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y --no-install-recommends "${missing[@]}"
else
  echo "headcast setup: all ${#packages[@]} Debian packages present"
fi

cmake -S "$root" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE="$build_type"
cmake --build "$root/build" -j "${HEADCAST_JOBS:-$(nproc)}"
echo "headcast setup: built into $root/build (programs in $root/build/bin)"
