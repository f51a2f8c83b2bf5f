#!/usr/bin/env bash
# The wheel as a user gets it: builds it (scripts/build-wheel.sh); checks that it is tagged
# manylinux2014 (manylinux_2_17) and earns it (auditwheel), and that neither the extension nor
# the `gridtrace` tool inside needs a glibc symbol newer than 2.17 or a library outside
# manylinux2014's list (objdump); installs it into a new virtual environment whose PATH has no
# Rust (no cargo, no rustc), and there runs a ray query, a render, the `gridtrace` tool the wheel
# put on PATH and `python -m gridtrace`. Fails, never skips, when anything is missing. Run by
# scripts/test.sh.
#
#   scripts/test-wheel.sh [CLI]     CLI: a cargo-built gridtrace whose --version the wheel's tool
#                                   must print too (default: target/release/gridtrace, if built)
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
target="${CARGO_TARGET_DIR:-$root/target}"
cargo_cli="${1:-$target/release/gridtrace}"
case "$cargo_cli" in /*) ;; *) cargo_cli="$root/$cargo_cli" ;; esac

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The folders as a user's target/ has them after `pip install ./crates/gridtrace-py` (maturin's
# linux_x86_64 wheel in wheels/) and an older build (another version in the manylinux folder):
# the README's `pip install` glob must still name one wheel, the new one.
arch=$(uname -m)
wheels="$tmp/wheels/manylinux2014-$arch"
mkdir -p "$wheels"
touch "$tmp/wheels/gridtrace-0.0.1-cp39-abi3-linux_$arch.whl"
touch "$wheels/gridtrace-0.0.1-cp39-abi3-manylinux_2_17_$arch.manylinux2014_$arch.whl"
WHEEL_PATH_FILE="$tmp/wheel-path" ./scripts/build-wheel.sh "$wheels"
whl=$(cat "$tmp/wheel-path")
shopt -s nullglob
matched=("$wheels"/gridtrace-*.whl)
shopt -u nullglob
if [ "${#matched[@]}" -ne 1 ] || [ "${matched[0]}" != "$whl" ]; then
    echo "test-wheel: the README's glob matches ${#matched[@]} wheels (${matched[*]}), want only $whl" >&2
    exit 1
fi

# The platform tag: in the name, and earned (auditwheel reads every ELF file in the wheel, the
# tool among them). auditwheel goes into .venv/ beside the build tools.
glibc=2.17
case "$(basename "$whl")" in
*manylinux_2_17_"$arch"*) ;;
*)
    echo "test-wheel: $(basename "$whl") is not tagged manylinux_2_17 (manylinux2014)" >&2
    exit 1
    ;;
esac
if [ ! -x .venv/bin/auditwheel ]; then
    .venv/bin/python -m pip install -q --disable-pip-version-check "auditwheel>=6,<7"
fi
show=$(.venv/bin/auditwheel show "$whl")
if ! grep -q "\"manylinux_2_17_$arch\"" <<<"$show"; then
    echo "test-wheel: auditwheel does not find $(basename "$whl") consistent with manylinux_2_17_$arch:" >&2
    echo "$show" >&2
    exit 1
fi
echo "test-wheel: auditwheel: consistent with manylinux_2_17_$arch"

# The binaries themselves: no glibc symbol version above 2.17, and only the libraries that
# manylinux2014 lets a wheel expect on the system (Vulkan, X11 and the like are opened with
# dlopen at run time, and only by the GPU and window code).
unpacked="$tmp/unpacked"
python3 -m zipfile -e "$whl" "$unpacked"
allowed=" libc.so.6 libm.so.6 libdl.so.2 libpthread.so.0 librt.so.1 libgcc_s.so.1 libutil.so.1 ld-linux-x86-64.so.2 ld-linux-aarch64.so.1 "
elves=("$unpacked"/gridtrace/_gridtrace*.so "$unpacked"/*.data/scripts/gridtrace)
for elf in "${elves[@]}"; do
    if [ ! -f "$elf" ]; then
        echo "test-wheel: $elf missing from the wheel" >&2
        exit 1
    fi
    need=$(objdump -T "$elf" | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -uV | tail -n 1)
    if [ -z "$need" ] || [ "$(printf '%s\n%s\n' "$need" "$glibc" | sort -V | tail -n 1)" != "$glibc" ]; then
        echo "test-wheel: ${elf#"$unpacked"/} needs glibc '${need}', above $glibc" >&2
        exit 1
    fi
    for lib in $(objdump -p "$elf" | awk '$1 == "NEEDED" { print $2 }'); do
        if [[ "$allowed" != *" $lib "* ]]; then
            echo "test-wheel: ${elf#"$unpacked"/} needs $lib, which manylinux2014 does not promise" >&2
            exit 1
        fi
    done
    echo "test-wheel: ${elf#"$unpacked"/}: newest glibc symbol $need, libraries: $(objdump -p "$elf" | awk '$1 == "NEEDED" { printf "%s ", $2 }')"
done

# PATH without any directory that holds cargo or rustc (~/.cargo/bin, a distribution's Rust).
clean_path=""
IFS=: read -r -a dirs <<<"$PATH"
for d in "${dirs[@]}"; do
    if [ -n "$d" ] && [ ! -e "$d/cargo" ] && [ ! -e "$d/rustc" ]; then
        clean_path="${clean_path:+$clean_path:}$d"
    fi
done

python3 -m venv "$tmp/venv"
venv="$tmp/venv"
export PATH="$venv/bin:$clean_path"
export VIRTUAL_ENV="$venv"
unset CARGO_TARGET_DIR RUSTUP_TOOLCHAIN
for tool in cargo rustc; do
    if command -v "$tool" >/dev/null 2>&1; then
        echo "test-wheel: $tool is still on PATH ($(command -v "$tool"))" >&2
        exit 1
    fi
done
# --only-binary: the wheel and its dependencies install as they are, nothing is compiled.
"$venv/bin/python" -m pip install -q --disable-pip-version-check --only-binary :all: "$whl"

# Run from the temporary folder, so that `import gridtrace` finds the installed package.
cd "$tmp"
"$venv/bin/python" - "$whl" <<'EOF'
import pathlib
import sys

import numpy as np

import gridtrace

# The installed package, not a source tree.
assert "site-packages" in pathlib.Path(gridtrace.__file__).parts, gridtrace.__file__
version = gridtrace.__version__
assert f"gridtrace-{version}-" in pathlib.Path(sys.argv[1]).name, (version, sys.argv[1])

# A ray query on a tiny mesh: two triangles of the square z = 0, x and y in [0, 2].
vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], np.float32)
faces = np.array([[0, 1, 2], [0, 2, 3]])
mesh = gridtrace.Mesh(vertices, faces, backend="cpu")
origins = np.array([[1.5, 0.5, 1.0], [0.5, 1.5, 2.0], [3.0, 3.0, 1.0]], np.float32)
hits = mesh.intersect(origins, [0.0, 0.0, -1.0])
assert hits.tri.tolist() == [0, 1, int(gridtrace.MISS)], hits
assert np.allclose(hits.t[:2], [1.0, 2.0]) and np.isinf(hits.t[2]), hits.t
assert np.allclose(hits.normal[:2], [[0, 0, 1], [0, 0, 1]]), hits.normal

# A render on the CPU: an image that is not one flat colour.
image = gridtrace.render("knot-box", 48, 32, mode="shadow", backend="cpu")
assert image.shape == (32, 48, 3) and image.dtype == np.uint8, (image.shape, image.dtype)
assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10, "flat image"
print(f"test-wheel: gridtrace {version}: query and render passed")
EOF

# The tool the wheel put on PATH: the environment's own, the same build as cargo's.
tool=$(command -v gridtrace || true)
if [ "$tool" != "$venv/bin/gridtrace" ]; then
    echo "test-wheel: the wheel did not install the gridtrace tool into $venv/bin (found: '${tool}')" >&2
    exit 1
fi
version=$(gridtrace --version)
echo "$version"
if [ "$(python -m gridtrace --version)" != "$version" ]; then
    echo "test-wheel: python -m gridtrace --version differs from gridtrace --version" >&2
    exit 1
fi
if [ ! -x "$cargo_cli" ]; then
    echo "test-wheel: no cargo-built tool at $cargo_cli to compare versions with (cargo build --release -p gridtrace-cli)" >&2
    exit 1
fi
if [ "$("$cargo_cli" --version)" != "$version" ]; then
    echo "test-wheel: cargo's tool says '$("$cargo_cli" --version)', the wheel's '$version'" >&2
    exit 1
fi
gridtrace render --scene knot-box --backend cpu --mode shadow --res 48x32 -o "$tmp/tool.png"
"$venv/bin/python" -c 'import sys; assert open(sys.argv[1], "rb").read(8) == b"\x89PNG\r\n\x1a\n"' "$tmp/tool.png"
echo "test-wheel: the wheel's gridtrace tool renders; its version agrees with cargo's"
