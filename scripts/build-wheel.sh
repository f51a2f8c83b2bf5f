#!/usr/bin/env bash
# Builds the Python wheel that installs without Rust: the extension module and the `gridtrace`
# command-line tool (installed into the environment's bin/, so on PATH in an active venv), both
# from the `dist` profile (stripped, thin LTO). One abi3 wheel serves CPython 3.9 and later; its
# manylinux tag is the lowest that the glibc symbols the binaries use allow (maturin's check).
#
#   scripts/build-wheel.sh [OUT_DIR]     default: target/wheels (or $CARGO_TARGET_DIR/wheels)
#
# Needs Rust, and maturin (>=1.7,<2) on PATH or in .venv/ (scripts/test.sh installs it there).
# Prints the wheel's path and size last; the wheel's path alone goes to $WHEEL_PATH_FILE if set.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
target="${CARGO_TARGET_DIR:-$root/target}"
out="${1:-$target/wheels}"

maturin=$(command -v maturin || true)
if [ -z "$maturin" ] && [ -x .venv/bin/maturin ]; then
    maturin=$root/.venv/bin/maturin
fi
if [ -z "$maturin" ]; then
    echo "build-wheel: maturin not found; install it: python3 -m pip install 'maturin>=1.7,<2'" >&2
    exit 1
fi

# 1. The command-line tool.
cargo build --profile dist --locked -p gridtrace-cli
cli="$target/dist/gridtrace"

# 2. The wheel. maturin packs a `<module>.data/scripts/` folder next to pyproject.toml into the
# wheel's scripts, which pip installs into the environment's bin/. The folder exists only while
# this script runs (and is ignored by git), so `maturin develop` and `pip install
# ./crates/gridtrace-py` do not ship a stale binary.
data=crates/gridtrace-py/gridtrace._gridtrace.data
tmp=$(mktemp -d)
cleanup() { rm -rf "$root/$data" "$tmp"; }
trap cleanup EXIT
rm -rf "$data"
mkdir -p "$data/scripts"
cp "$cli" "$data/scripts/gridtrace"
chmod 755 "$data/scripts/gridtrace"
"$maturin" build --profile dist --locked --auditwheel check -m crates/gridtrace-py/Cargo.toml --out "$tmp"

shopt -s nullglob
wheels=("$tmp"/*.whl)
if [ "${#wheels[@]}" -ne 1 ]; then
    echo "build-wheel: expected one wheel from maturin, got ${#wheels[@]}" >&2
    exit 1
fi
whl=${wheels[0]}
if ! python3 -m zipfile -l "$whl" | grep -q "\.data/scripts/gridtrace "; then
    echo "build-wheel: the wheel lacks the gridtrace tool (data/scripts)" >&2
    exit 1
fi

# maturin's manylinux check covers the extension; the tool must need no newer glibc than the tag
# promises either.
tag=$(basename "$whl" .whl | sed -n 's/.*manylinux_\([0-9]*\)_\([0-9]*\)_.*/\1.\2/p')
if [ -n "$tag" ] && command -v objdump >/dev/null 2>&1; then
    need=$(objdump -T "$cli" | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -uV | tail -n 1)
    if [ -n "$need" ] && [ "$(printf '%s\n%s\n' "$need" "$tag" | sort -V | tail -n 1)" != "$tag" ]; then
        echo "build-wheel: the tool needs glibc $need, newer than the wheel's manylinux tag ($tag)" >&2
        exit 1
    fi
fi

mkdir -p "$out"
dest="$out/$(basename "$whl")"
mv -f "$whl" "$dest"
if [ -n "${WHEEL_PATH_FILE:-}" ]; then
    printf '%s\n' "$dest" >"$WHEEL_PATH_FILE"
fi
bytes=$(stat -c %s "$dest")
echo "wheel: $dest"
echo "size: $bytes bytes ($(awk -v b="$bytes" 'BEGIN { printf "%.1f", b / 1048576 }') MiB)"
