#!/usr/bin/env bash
# Builds the web page into web/dist: the library and crates/gridtrace-web compiled to
# wasm32-unknown-unknown (release), wasm-bindgen's JS glue, index.html and main.js. Prints the
# files' sizes; fails if the wasm is over 5 MB (uncompressed).
#
# Needs: rustup target add wasm32-unknown-unknown; wasm-bindgen-cli of the very version of the
# wasm-bindgen crate in Cargo.lock (cargo install wasm-bindgen-cli --version X.Y.Z).
# Serve it:  python3 -m http.server -d web/dist 8000   (then open http://localhost:8000/)
set -euo pipefail
cd "$(dirname "$0")/.."

want=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
have=$(wasm-bindgen --version 2>/dev/null | awk '{ print $2 }' || true)
if [ "$have" != "$want" ]; then
    echo "wasm-bindgen-cli $want is needed (found: ${have:-none}): cargo install wasm-bindgen-cli --version $want" >&2
    exit 1
fi

target_dir=${CARGO_TARGET_DIR:-target}
cargo build --release --target wasm32-unknown-unknown -p gridtrace-web
rm -rf web/dist
mkdir -p web/dist
wasm-bindgen --target web --no-typescript --out-dir web/dist \
    "$target_dir/wasm32-unknown-unknown/release/gridtrace_web.wasm"
cp web/index.html web/main.js web/dist/

wasm=web/dist/gridtrace_web_bg.wasm
ls -l web/dist | awk 'NR > 1 { printf "%10d  %s\n", $5, $9 }'
bytes=$(stat -c %s "$wasm")
limit=$((5 * 1000 * 1000))
if [ "$bytes" -gt "$limit" ]; then
    echo "$wasm is $bytes bytes: over the 5 MB the page allows itself" >&2
    exit 1
fi
echo "wasm $bytes bytes (limit $limit)"
