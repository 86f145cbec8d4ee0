#!/usr/bin/env bash
# Sets up (packages + Release build) and runs every test with CTest. Benchmarks live in bench/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
# The web viewer's npm packages (web/package-lock.json), for the Web.* tests.
(cd web && npm ci --no-audit --no-fund --loglevel=error)
cd build
ctest --output-on-failure --timeout 900 -j "$(nproc)"
