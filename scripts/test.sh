#!/usr/bin/env bash
# Sets up (packages + Release build) and runs every test with CTest. Benchmarks live in bench/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
cd build
ctest --output-on-failure --timeout 900 -j "$(nproc)"
