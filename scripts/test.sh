#!/usr/bin/env bash
# Newcomer command 2: set up, build, and run the whole test suite (ctest).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
cd "${BUILD_DIR:-$root/build}"
if ctest --output-on-failure -j "$(nproc)" --timeout 900; then
  echo "TESTS PASSED"
else
  echo "TESTS FAILED"
  exit 1
fi
