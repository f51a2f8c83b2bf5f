#!/usr/bin/env bash
# Runs every test of the project: the Rust workspace (CPU and GPU; the GPU tests need a Vulkan
# adapter, lavapipe will do: `apt-get install mesa-vulkan-drivers`).
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa's software Vulkan complains loudly when this is unset; give it a private directory.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    export XDG_RUNTIME_DIR="$(mktemp -d)"
fi
cargo test --workspace --locked
