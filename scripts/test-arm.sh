#!/usr/bin/env bash
# The aarch64 wheel on an emulated ARM machine, against the x86-64 wheel on the same inputs.
#
# 1. root: an arm64 Debian bookworm root with python3, numpy and pip, made once from Debian's
#    packages (`mmdebstrap --arch=arm64 --variant=extract`: the packages are unpacked, none of
#    their scripts run, so no binfmt is needed; the two library links that Debian's
#    `update-alternatives` would make for numpy's BLAS/LAPACK are made here, and the standard
#    library is byte-compiled once under emulation so that later runs do not recompile it).
#    Kept in $ARM_ROOT (default: target/arm64-root); remove it to make it again.
# 2. wheels: the aarch64 wheel (scripts/build-wheel.sh --target aarch64-unknown-linux-gnu) and
#    this machine's x86-64 one (scripts/build-wheel.sh), each built only if missing.
# 3. x86-64: the x86-64 wheel installed into a new venv; the queries and renders below.
# 4. aarch64: every aarch64 program runs as `qemu-aarch64-static -L ROOT PROGRAM` (qemu-user,
#    no binfmt, no chroot): a venv of the root's python3 (with the root's numpy), the wheel
#    installed into it by the root's pip, the queries and renders below, `gridtrace --version`.
# 5. compare: the same answers. Hits: the same misses; t within 1e-6 relative; the same
#    triangle except ties (both triangles share an edge or a vertex and the hit point lies on
#    it: counted, and bounded by the rays aimed at edges and vertices plus 0.1% of the others);
#    u, v and normal within 1e-5 where the triangle is the same; occlusion the same. Renders
#    (Python and the CLI, --backend cpu): pixels the same except at most 0.1% off by at most 2.
#    Any other difference fails the script.
#
# The queries: the wheel test's (scripts/test-wheel.sh: a two-triangle square, a knot-box
# render, the CLI's render) and a torus of 2048 triangles hit by random rays, camera rays (the
# packet paths) and rays aimed at its edges and vertices, through every CPU structure.
#
# Time (2 cores, shared with other builds, 2026-11-28): 36 s when the root and both wheels
# exist (x86-64 11 s, the aarch64 install 5 s, its queries and renders 17 s); making the root
# adds about 2.5 min, once. The wheels are what is slow: the aarch64 one is a cross release
# build of everything, about 35 min from an empty target folder here. That, and what it needs
# besides (qemu-user-static for qemu-aarch64-static; mmdebstrap, run as root or in its unshare
# mode, and Debian's mirror for step 1; PyPI for the x86-64 venv's numpy), keeps it out of
# scripts/test.sh.
#
#   scripts/test-arm.sh        env: ARM_ROOT, ARM_WHEEL, X86_WHEEL (paths; defaults above and
#                              target/wheels/manylinux2014-{aarch64,x86_64}/gridtrace-*.whl)
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
target="${CARGO_TARGET_DIR:-$root/target}"
arm_root="${ARM_ROOT:-$target/arm64-root}"
case "$arm_root" in /*) ;; *) arm_root="$root/$arm_root" ;; esac
if [ "$(uname -m)" != x86_64 ]; then
    echo "test-arm: runs on an x86-64 machine (it compares the emulated aarch64 build with this machine's x86-64 one)" >&2
    exit 1
fi
qemu=$(command -v qemu-aarch64-static || true)
if [ -z "$qemu" ]; then
    echo "test-arm: qemu-aarch64-static not found (Debian: apt-get install qemu-user-static)" >&2
    exit 1
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
phase_start=$(date +%s)
script_start=$phase_start
phase() {
    local now
    now=$(date +%s)
    echo "test-arm: [$1: $((now - phase_start)) s]"
    phase_start=$now
}
# An aarch64 program under emulation, its absolute paths looked up in the root first.
arm() { "$qemu" -L "$arm_root" "$@"; }

# 1. The root. The stamp is written last, so a root that was cut short is made again.
stamp="$arm_root/.gridtrace-test-arm"
if [ ! -f "$stamp" ]; then
    if ! command -v mmdebstrap >/dev/null 2>&1; then
        echo "test-arm: mmdebstrap not found (Debian: apt-get install mmdebstrap)" >&2
        exit 1
    fi
    rm -rf "$arm_root"
    mkdir -p "$(dirname "$arm_root")"
    echo "test-arm: making the arm64 root in $arm_root"
    mmdebstrap --quiet --arch=arm64 --variant=extract --include=python3,python3-numpy,python3-pip \
        bookworm "$arm_root"
    libs="$arm_root/usr/lib/aarch64-linux-gnu"
    ln -sfn blas/libblas.so.3 "$libs/libblas.so.3"
    ln -sfn lapack/liblapack.so.3 "$libs/liblapack.so.3"
    py=("$arm_root"/usr/lib/python3.*)
    env -u PYTHONDONTWRITEBYTECODE "$qemu" -L "$arm_root" "$arm_root/usr/bin/python3" \
        -m compileall -q -j 0 "${py[0]}" "$arm_root/usr/lib/python3/dist-packages" >/dev/null
    touch "$stamp"
fi
arm "$arm_root/usr/bin/python3" -c 'import platform, numpy; assert platform.machine() == "aarch64", platform.machine()'
phase root

# 2. The wheels.
wheel_for() { # ARCH ENV_VALUE: the wheel to use, built if missing
    local arch=$1 given=$2
    if [ -n "$given" ]; then
        echo "$given"
        return
    fi
    local found=("$target/wheels/manylinux2014-$arch"/gridtrace-*.whl)
    if [ ! -f "${found[0]}" ]; then
        ./scripts/build-wheel.sh --target "$arch-unknown-linux-gnu" >&2
        found=("$target/wheels/manylinux2014-$arch"/gridtrace-*.whl)
    fi
    echo "${found[0]}"
}
arm_wheel=$(wheel_for aarch64 "${ARM_WHEEL:-}")
x86_wheel=$(wheel_for x86_64 "${X86_WHEEL:-}")
for w in "$arm_wheel" "$x86_wheel"; do
    if [ ! -f "$w" ]; then
        echo "test-arm: no wheel at $w" >&2
        exit 1
    fi
done
case "$(basename "$arm_wheel")" in
*manylinux_2_17_aarch64*) ;;
*)
    echo "test-arm: $(basename "$arm_wheel") is not tagged manylinux_2_17_aarch64" >&2
    exit 1
    ;;
esac
echo "test-arm: aarch64: $arm_wheel"
echo "test-arm: x86-64:  $x86_wheel"
phase wheels

# The inputs, made once on the host (step 3) and read by both sides: a torus (every edge shared by
# two triangles), random rays from a box around it, a pinhole camera's rays (coherent: the
# packet paths) and rays aimed exactly at edge midpoints and vertices (ties).
cat >"$tmp/inputs.py" <<'EOF'
import sys

import numpy as np

rng = np.random.default_rng(56)
# Torus: major radius 1, minor 0.35, 32 x 32 quads, each split into two triangles.
n_u, n_v = 32, 32
a, b = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
phi, theta = 2 * np.pi * a / n_u, 2 * np.pi * b / n_v
r = 1.0 + 0.35 * np.cos(theta)
vertices = np.stack([r * np.cos(phi), r * np.sin(phi), 0.35 * np.sin(theta)], -1).reshape(-1, 3).astype(np.float32)
idx = lambda i, j: (i % n_u) * n_v + (j % n_v)
faces = []
for i in range(n_u):
    for j in range(n_v):
        faces.append([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)])
        faces.append([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)])
faces = np.array(faces, np.uint32)

def unit(d):
    return (d / np.linalg.norm(d, axis=-1, keepdims=True)).astype(np.float32)

# Random rays: origins in a box around the torus, directions towards a random point near it.
n = 4000
o_rand = rng.uniform(-2.5, 2.5, (n, 3)).astype(np.float32)
d_rand = unit(rng.uniform(-1.2, 1.2, (n, 3)) - o_rand)
# Camera rays: 64 x 48 pixels from (0, -4, 2.5) towards the origin.
w, h = 64, 48
eye = np.array([0.0, -4.0, 2.5])
fwd = -eye / np.linalg.norm(eye)
right = np.cross(fwd, [0.0, 0.0, 1.0]); right /= np.linalg.norm(right)
up = np.cross(right, fwd)
px, py = np.meshgrid((np.arange(w) + 0.5) / w * 2 - 1, (np.arange(h) + 0.5) / h * 2 - 1)
d_cam = unit(fwd + 0.6 * (px[..., None] * right * w / h - py[..., None] * up)).reshape(-1, 3)
o_cam = np.broadcast_to(eye, d_cam.shape).astype(np.float32)
# Aimed rays: at the midpoints of 300 edges (diagonals and grid edges) and at 100 vertices,
# from random points 3 to 4 away.
tri = faces[rng.integers(0, len(faces), 300)]
k = rng.integers(0, 3, 300)
p_edge = (vertices[tri[np.arange(300), k]].astype(np.float64) + vertices[tri[np.arange(300), (k + 1) % 3]]) / 2
p_vert = vertices[rng.integers(0, len(vertices), 100)].astype(np.float64)
p_aim = np.concatenate([p_edge, p_vert])
o_aim = (p_aim + unit(rng.normal(size=p_aim.shape)) * rng.uniform(3, 4, (len(p_aim), 1))).astype(np.float32)
d_aim = unit(p_aim - o_aim)
np.savez(
    sys.argv[1], vertices=vertices, faces=faces,
    origins=np.concatenate([o_rand, o_cam, o_aim]), directions=np.concatenate([d_rand, d_cam, d_aim]),
    n_random=n, n_camera=w * h, n_aimed=len(p_aim),
)
EOF

# The queries, the same program on both sides: the wheel test's checks, then every CPU
# structure's answers on the inputs, and a render through Python, all into one .npz.
cat >"$tmp/queries.py" <<'EOF'
import pathlib
import platform
import sys

import numpy as np

import gridtrace

assert "site-packages" in pathlib.Path(gridtrace.__file__).parts, gridtrace.__file__
print(f"test-arm: {platform.machine()}: gridtrace {gridtrace.__version__}, numpy {np.__version__}, python {platform.python_version()}")

# The wheel test's query: two triangles of the square z = 0, x and y in [0, 2].
vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], np.float32)
faces = np.array([[0, 1, 2], [0, 2, 3]])
mesh = gridtrace.Mesh(vertices, faces, backend="cpu")
origins = np.array([[1.5, 0.5, 1.0], [0.5, 1.5, 2.0], [3.0, 3.0, 1.0]], np.float32)
hits = mesh.intersect(origins, [0.0, 0.0, -1.0])
assert hits.tri.tolist() == [0, 1, int(gridtrace.MISS)], hits
assert np.allclose(hits.t[:2], [1.0, 2.0]) and np.isinf(hits.t[2]), hits.t
assert np.allclose(hits.normal[:2], [[0, 0, 1], [0, 0, 1]]), hits.normal

inputs = np.load(sys.argv[1])
out = {}
for accel in ["grid", "pc", "bvh", "irregular", "brute"]:
    mesh = gridtrace.Mesh(inputs["vertices"], inputs["faces"], accel=accel, backend="cpu")
    h = mesh.intersect(inputs["origins"], inputs["directions"])
    for field in h._fields:
        out[f"{accel}.{field}"] = getattr(h, field)
    out[f"{accel}.occluded"] = mesh.occluded(inputs["origins"], inputs["directions"])

image = gridtrace.render("knot-box", 96, 64, mode="shadow", backend="cpu")
assert image.shape == (64, 96, 3) and image.dtype == np.uint8, (image.shape, image.dtype)
assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10, "flat image"
out["render"] = image
np.savez(sys.argv[2], **out)
print(f"test-arm: {platform.machine()}: the wheel test's query and render passed; {len(inputs['origins'])} rays through 5 structures")
EOF
render_args=(render --scene knot-box --backend cpu --mode shadow --res 96x64)

# 3. x86-64.
python3 -m venv "$tmp/x86"
"$tmp/x86/bin/python" -m pip install -q --disable-pip-version-check --only-binary :all: "$x86_wheel"
"$tmp/x86/bin/python" "$tmp/inputs.py" "$tmp/inputs.npz"
(cd "$tmp" && "$tmp/x86/bin/python" queries.py inputs.npz x86.npz)
"$tmp/x86/bin/gridtrace" "${render_args[@]}" -o "$tmp/x86.png"
phase x86-64

# 4. aarch64. The venv sees the root's numpy and pip (system site packages); pip installs the
# wheel from the file alone (no index) and checks its tags against the emulated machine's.
arm "$arm_root/usr/bin/python3" -m venv --system-site-packages --without-pip "$tmp/arm"
arm "$tmp/arm/bin/python" -m pip install -q --disable-pip-version-check --no-index "$arm_wheel"
phase "aarch64 install"
(cd "$tmp" && arm "$tmp/arm/bin/python" queries.py inputs.npz arm.npz)
arm_version=$(arm "$tmp/arm/bin/gridtrace" --version)
echo "test-arm: aarch64 gridtrace --version:"
sed 's/^/    /' <<<"$arm_version"
if ! grep -q "^cpu: aarch64 with NEON" <<<"$arm_version"; then
    echo "test-arm: the aarch64 tool's --version does not name its NEON paths" >&2
    exit 1
fi
arm "$tmp/arm/bin/gridtrace" "${render_args[@]}" -o "$tmp/arm.png"
phase "aarch64 queries and render"

# 5. Compare.
"$tmp/x86/bin/python" - "$tmp" <<'EOF'
import sys
import zlib

import numpy as np

tmp = sys.argv[1]
inputs = np.load(f"{tmp}/inputs.npz")
x86, arm = np.load(f"{tmp}/x86.npz"), np.load(f"{tmp}/arm.npz")
faces = inputs["faces"]
vertices = inputs["vertices"].astype(np.float64)
n_random, n_camera, n_aimed = int(inputs["n_random"]), int(inputs["n_camera"]), int(inputs["n_aimed"])
aimed = np.zeros(len(inputs["origins"]), bool)
aimed[n_random + n_camera:] = True
scale = np.ptp(vertices, axis=0).max()
failures = []


def on_shared(p, ta, tb):
    """Whether hit point p lies on what triangles ta and tb share (an edge or a vertex)."""
    shared = sorted(set(faces[ta].tolist()) & set(faces[tb].tolist()))
    if not shared:
        return False, 0
    if len(shared) == 1:
        d = np.linalg.norm(p - vertices[shared[0]])
    else:
        a, b = vertices[shared[0]], vertices[shared[1]]
        s = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
        d = np.linalg.norm(p - (a + s * (b - a)))
    return d <= 1e-5 * scale, len(shared)


total_ties = 0
for accel in ["grid", "pc", "bvh", "irregular", "brute"]:
    g = lambda side, f: side[f"{accel}.{f}"]
    t_x, t_a = g(x86, "t"), g(arm, "t")
    tri_x, tri_a = g(x86, "tri"), g(arm, "tri")
    miss_x, miss_a = np.isinf(t_x), np.isinf(t_a)
    if (miss_x != miss_a).any():
        failures.append(f"{accel}: {np.count_nonzero(miss_x != miss_a)} rays hit on one machine only")
        continue
    hit = ~miss_x
    rel = np.abs(t_x[hit] - t_a[hit]) / np.maximum(np.abs(t_x[hit]), 1e-30)
    if (rel > 1e-6).any():
        failures.append(f"{accel}: t differs by up to {rel.max():.3g} relative (> 1e-6) on {np.count_nonzero(rel > 1e-6)} rays")
    ties = {1: 0, 2: 0}
    ties_random = 0
    for i in np.nonzero(hit & (tri_x != tri_a))[0]:
        p = inputs["origins"][i].astype(np.float64) + float(t_x[i]) * inputs["directions"][i].astype(np.float64)
        ok, n_shared = on_shared(p, int(tri_x[i]), int(tri_a[i]))
        if not ok:
            failures.append(f"{accel}: ray {i}: triangle {tri_x[i]} (x86-64) against {tri_a[i]} (aarch64), not a tie at a shared edge or vertex")
            continue
        ties[n_shared] += 1
        ties_random += not aimed[i]
    n_ties = ties[1] + ties[2]
    total_ties += n_ties
    bound = n_aimed + int(0.001 * (n_random + n_camera))
    if n_ties > bound or ties_random > int(0.001 * (n_random + n_camera)):
        failures.append(f"{accel}: {n_ties} ties ({ties_random} on rays not aimed at edges), above the bound {bound}")
    same = hit & (tri_x == tri_a)
    for f in ["u", "v", "normal"]:
        d = np.abs(g(x86, f)[same] - g(arm, f)[same]).max()
        if d > 1e-5:
            failures.append(f"{accel}: {f} differs by {d:.3g} (> 1e-5) where the triangle is the same")
    occ = g(x86, "occluded") != g(arm, "occluded")
    if occ.any():
        failures.append(f"{accel}: occluded differs on {np.count_nonzero(occ)} rays")
    print(
        f"test-arm: {accel:9s} {np.count_nonzero(hit)} of {len(hit)} rays hit on both, t within "
        f"{rel.max() if hit.any() else 0:.2g} relative; ties: {ties[2]} at shared edges, {ties[1]} at shared vertices "
        f"({ties_random} on rays not aimed at them)"
    )


def png_pixels(path):
    """The pixels of an 8-bit RGB or RGBA PNG (what the CLI writes), without a PNG library."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat = 8, b""
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour, interlace = int.from_bytes(body[:4], "big"), int.from_bytes(body[4:8], "big"), body[8], body[9], body[12]
            assert depth == 8 and colour in (2, 6) and interlace == 0, (path, depth, colour, interlace)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    bpp = 3 if colour == 2 else 4
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], np.zeros(stride, np.int32)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        out = np.zeros(stride, np.int32)
        for x in range(stride):
            left = out[x - bpp] if x >= bpp else 0
            up, ul = prev[x], (prev[x - bpp] if x >= bpp else 0)
            if f == 0:
                pred = 0
            elif f == 1:
                pred = left
            elif f == 2:
                pred = up
            elif f == 3:
                pred = (left + up) // 2
            else:
                pa, pb, pc = abs(up - ul), abs(left - ul), abs(left + up - 2 * ul)
                pred = left if pa <= pb and pa <= pc else (up if pb <= pc else ul)
            out[x] = (line[x] + pred) & 255
        rows.append(out)
        prev = out
    return np.array(rows).reshape(h, w, bpp)


def compare_images(name, a, b):
    if a.shape != b.shape:
        failures.append(f"{name}: shapes {a.shape} and {b.shape}")
        return
    diff = np.abs(a.astype(np.int32) - b.astype(np.int32)).max(axis=-1)
    off = np.count_nonzero(diff)
    if off > 0.001 * diff.size or diff.max() > 2:
        failures.append(f"{name}: {off} of {diff.size} pixels differ, by up to {diff.max()}")
    print(f"test-arm: {name}: {off} of {diff.size} pixels differ (by up to {diff.max()})")


compare_images("Python render", x86["render"], arm["render"])
compare_images("CLI render", png_pixels(f"{tmp}/x86.png"), png_pixels(f"{tmp}/arm.png"))
if failures:
    print("test-arm: aarch64 and x86-64 disagree:", *failures, sep="\n    ", file=sys.stderr)
    sys.exit(1)
print(f"test-arm: the same answers on aarch64 and x86-64 ({total_ties} ties in all)")
EOF
phase compare
echo "test-arm: passed in $(($(date +%s) - script_start)) s"
