#!/usr/bin/env bash
# Sets headcast up (packages + build), then runs the whole test suite with ctest.
# Select tests by label with HEADCAST_TEST_LABELS (e.g. "unit", "data", "slow").
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
"$root/deploy/setup.sh"
args=(--test-dir "$root/build" --output-on-failure -j "${HEADCAST_TEST_JOBS:-2}")
[ -n "${HEADCAST_TEST_LABELS:-}" ] && args+=(-L "$HEADCAST_TEST_LABELS")
if [ ! -d "${HEADCAST_DATA:-$root/../shared/data}" ]; then
  echo "headcast test: no shared data at ${HEADCAST_DATA:-$root/../shared/data}; data-labelled tests will skip"
fi
ctest "${args[@]}"
