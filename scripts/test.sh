#!/usr/bin/env bash
# Runs every test of the project: the Rust workspace (CPU and GPU) and the Python package.
# Needs Rust, python3 (with venv) and, for the GPU tests, a Vulkan adapter: lavapipe will do
# (`apt-get install mesa-vulkan-drivers`), and for the window tests a display or Xvfb (`xvfb`).
# Python packages go into .venv/ (created here).
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa's software Vulkan complains loudly when this is unset; give it a private directory.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    export XDG_RUNTIME_DIR="$(mktemp -d)"
fi

# The viewer's window tests need a display: a virtual one (Xvfb) when there is none. Without
# either they fail under CI=1 and are skipped (with a message) otherwise.
run=()
if [ -z "${DISPLAY:-}" ] && command -v xvfb-run >/dev/null 2>&1; then
    run=(xvfb-run -a)
fi
"${run[@]}" cargo test --workspace --exclude gridtrace-py --locked

# Python: build the extension into a virtual environment, then pytest (the tests compare with
# the release CLI on the same rays).
cargo build --release --locked -p gridtrace-cli
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
# trimesh (with rtree and scipy for its own ray engine, the reference) and Dask are optional
# dependencies of the package; their tests need them.
.venv/bin/python -m pip install -q --disable-pip-version-check "maturin>=1.7,<2" numpy pytest trimesh rtree scipy "dask[distributed]"
VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" maturin develop --release --locked -q -m crates/gridtrace-py/Cargo.toml
GRIDTRACE_BIN="${CARGO_TARGET_DIR:-$PWD/target}/release/gridtrace" .venv/bin/python -m pytest -q crates/gridtrace-py/tests

# The web page in a real browser: the library built for wasm32 with wasm-bindgen's glue
# (scripts/build-web.sh), Debian's chromium (`apt-get install chromium`; .ci/run installs it)
# driven by Playwright from PyPI, with no browser download; each image compared with the
# release CLI's.
rustup target add wasm32-unknown-unknown >/dev/null
bindgen=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
if [ "$(wasm-bindgen --version 2>/dev/null | awk '{ print $2 }')" != "$bindgen" ]; then
    cargo install -q wasm-bindgen-cli --version "$bindgen"
fi
.venv/bin/python -m pip install -q --disable-pip-version-check "playwright==1.65.2" pillow
GRIDTRACE_BIN="${CARGO_TARGET_DIR:-$PWD/target}/release/gridtrace" PYTHON=.venv/bin/python ./scripts/test-web.sh

# The wheel as users get it: built with the dist profile (scripts/build-wheel.sh), installed into
# a new environment without Rust, where a query, a render and its gridtrace tool (whose version
# must be the release build's above) run.
./scripts/test-wheel.sh "${CARGO_TARGET_DIR:-$PWD/target}/release/gridtrace"
