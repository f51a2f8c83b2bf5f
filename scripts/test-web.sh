#!/usr/bin/env bash
# The web page's tests in a real browser: builds web/dist (scripts/build-web.sh) and the
# release CLI (the reference images), then runs web/tests with PYTHON (default python3), which
# needs pytest, playwright (from PyPI; no browser download: Debian's chromium is used), pillow
# and numpy. GRIDTRACE_DATA_DIR names the mesh folder of the Stanford Bunny case (default:
# ../shared/data/meshes beside the checkout).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build-web.sh
if [ -z "${GRIDTRACE_BIN:-}" ]; then
    cargo build --release -p gridtrace-cli
    export GRIDTRACE_BIN="${CARGO_TARGET_DIR:-target}/release/gridtrace"
fi
"${PYTHON:-python3}" -m pytest -s -rsx web/tests "$@"
