#!/usr/bin/env bash
# Builds the Python wheel that installs without Rust on any x86-64 (or aarch64) Linux with glibc
# 2.17 or newer, tagged manylinux2014 (manylinux_2_17): RHEL/CentOS 7, 8 and 9, Debian 9 and
# later, Ubuntu 18.04 and later, Amazon Linux 2. It holds the extension module and the
# `gridtrace` command-line tool (installed into the environment's bin/, so on PATH in an active
# venv), both from the `dist` profile (stripped, thin LTO), both linked by zig against glibc
# 2.17's symbols whatever glibc the build machine has: no container. One abi3 wheel serves
# CPython 3.9 and later.
#
#   scripts/build-wheel.sh [--target TRIPLE] [OUT_DIR]
#       TRIPLE: x86_64-unknown-linux-gnu or aarch64-unknown-linux-gnu; default: this machine's.
#               Another machine's is a cross build (zig links for it; `rustup target add
#               TRIPLE` once): from x86-64, the aarch64 wheel that scripts/test-arm.sh tests.
#       OUT_DIR default: target/wheels/manylinux2014-ARCH (ARCH: x86_64 or aarch64, the
#               triple's first part; under $CARGO_TARGET_DIR if set)
#
# The folder holds one wheel: an older build's gridtrace wheel for the same machine is removed,
# so `pip install target/wheels/manylinux2014-x86_64/gridtrace-*.whl` names exactly one. (Not
# target/wheels itself: `pip install ./crates/gridtrace-py` leaves its own linux_x86_64 wheel
# there, maturin's build directory, and pip refuses two gridtrace wheels at once.)
#
# Needs Rust and python3. The build tools come from PyPI into .venv/ (made if missing) unless
# they are there already: maturin and ziglang (zig, the linker). Prints the wheel's path and
# size last; the wheel's path alone goes to $WHEEL_PATH_FILE if set.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
target="${CARGO_TARGET_DIR:-$root/target}"

# The oldest glibc the binaries may need: manylinux2014's.
glibc=2.17
triple="$(uname -m)-unknown-linux-gnu"
if [ "${1:-}" = "--target" ]; then
    if [ -z "${2:-}" ]; then
        echo "build-wheel: --target needs a triple (x86_64-unknown-linux-gnu or aarch64-unknown-linux-gnu)" >&2
        exit 2
    fi
    triple=$2
    shift 2
fi
case "$triple" in
x86_64-unknown-linux-gnu | aarch64-unknown-linux-gnu) ;;
*)
    echo "build-wheel: --target $triple: not a manylinux2014 target this script builds (x86_64-unknown-linux-gnu or aarch64-unknown-linux-gnu)" >&2
    exit 2
    ;;
esac
arch=${triple%%-*}
out="${1:-$target/wheels/manylinux2014-$arch}"
# The host's objdump may not read another machine's ELF files: the cross binutils' then.
objdump=objdump
if [ "$arch" != "$(uname -m)" ] && command -v "$arch-linux-gnu-objdump" >/dev/null 2>&1; then
    objdump="$arch-linux-gnu-objdump"
fi

tmp=$(mktemp -d)
data=crates/gridtrace-py/gridtrace._gridtrace.data
cleanup() { rm -rf "$root/$data" "$tmp"; }
trap cleanup EXIT

# 1. The tools, in .venv/ (scripts/test.sh's environment). Versions known to work together.
tools=("maturin>=1.7,<2" "ziglang==0.17.1")
venv=$root/.venv
if [ ! -x "$venv/bin/maturin" ] || ! "$venv/bin/python" -m ziglang version >/dev/null 2>&1; then
    [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
    echo "build-wheel: installing ${tools[*]} into $venv" >&2
    "$venv/bin/python" -m pip install -q --disable-pip-version-check "${tools[@]}"
fi
# maturin finds zig as `python3 -m ziglang`: the venv's python first on PATH.
export PATH="$venv/bin:$PATH"
# `--zig` links with zig against the glibc that `--compatibility` names, and the target is
# named, so the binaries go to $target/$triple/dist.
zig=(--profile dist --locked --zig --target "$triple" --compatibility manylinux2014 --auditwheel check)

# 2. The command-line tool, built by maturin as a `bin` wheel whose binary is all we keep. Not
# by cargo-zigbuild: cargo counts the linker among a crate's settings, and the two tools link
# through wrappers of different paths, so every crate the tool shares with the extension would
# be built twice. Through maturin both builds share them (and auditwheel checks the tool).
maturin build "${zig[@]}" -b bin -m crates/gridtrace-cli/Cargo.toml --out "$tmp/tool"
cli="$target/$triple/dist/gridtrace"

# 3. The wheel. maturin packs a `<module>.data/scripts/` folder next to pyproject.toml into the
# wheel's scripts, which pip installs into the environment's bin/. The folder exists only while
# this script runs (and is ignored by git), so `maturin develop` and `pip install
# ./crates/gridtrace-py` do not ship a stale binary. `--auditwheel check` fails the build if
# the tag is not earned.
rm -rf "$data"
mkdir -p "$data/scripts"
cp "$cli" "$data/scripts/gridtrace"
chmod 755 "$data/scripts/gridtrace"
maturin build "${zig[@]}" -m crates/gridtrace-py/Cargo.toml --out "$tmp/wheel"

shopt -s nullglob
wheels=("$tmp"/wheel/*.whl)
if [ "${#wheels[@]}" -ne 1 ]; then
    echo "build-wheel: expected one wheel from maturin, got ${#wheels[@]}" >&2
    exit 1
fi
whl=${wheels[0]}
case "$(basename "$whl")" in
*manylinux_2_17_"$arch"* | *manylinux2014_"$arch"*) ;;
*)
    echo "build-wheel: $(basename "$whl") is not tagged manylinux2014 / manylinux_2_17" >&2
    exit 1
    ;;
esac
# The listing is taken whole first: `grep -q` stops reading at its match, and under pipefail
# the lister's broken pipe would fail the check of a wheel that has the tool.
listing=$(python3 -m zipfile -l "$whl")
if ! grep -q "\.data/scripts/gridtrace " <<<"$listing"; then
    echo "build-wheel: the wheel lacks the gridtrace tool (data/scripts)" >&2
    exit 1
fi

# maturin's check covers the extension; the tool must need no newer glibc than the tag promises
# either (scripts/test-wheel.sh checks both again, from the wheel itself).
if command -v "$objdump" >/dev/null 2>&1; then
    need=$("$objdump" -T "$cli" | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -uV | tail -n 1)
    if [ -n "$need" ] && [ "$(printf '%s\n%s\n' "$need" "$glibc" | sort -V | tail -n 1)" != "$glibc" ]; then
        echo "build-wheel: the tool needs glibc $need, newer than the wheel's manylinux tag ($glibc)" >&2
        exit 1
    fi
fi

mkdir -p "$out"
dest="$out/$(basename "$whl")"
# One wheel per machine in the folder: older builds' (other versions) go.
for old in "$out"/gridtrace-*_"$arch".whl; do
    if [ "$old" != "$dest" ]; then
        rm -f "$old"
    fi
done
mv -f "$whl" "$dest"
if [ -n "${WHEEL_PATH_FILE:-}" ]; then
    printf '%s\n' "$dest" >"$WHEEL_PATH_FILE"
fi
bytes=$(stat -c %s "$dest")
echo "wheel: $dest"
echo "size: $bytes bytes ($(awk -v b="$bytes" 'BEGIN { printf "%.1f", b / 1048576 }') MiB)"
