#!/usr/bin/env bash
# Runs the peers' own ray tests against gridtrace, unchanged, through the pytest plugins in
# peer_shims/: Open3D's python/test/t/geometry/test_raycasting_scene.py with gridtrace.Scene in
# the place of open3d.t.geometry.RaycastingScene, and trimesh's tests/test_ray.py and
# tests/test_ray_upstream.py with gridtrace.trimesh as trimesh's accelerated (Embree) engine.
#
# It downloads nothing and holds none of the peers' code: give it their files from your own
# checkouts or source archives.
#
#   crates/gridtrace-py/bench/peer_tests.sh [--open3d FILE] [--trimesh DIR] [--both] [-- PYTEST_ARGS]
#
#   --open3d FILE  Open3D's test_raycasting_scene.py (a copy anywhere; v0.18.0 and v0.19.0 run).
#   --trimesh DIR  trimesh's tests/ folder: test_ray.py, test_ray_upstream.py and generic.py, with
#                  trimesh's models/ beside it (generic.py loads ../models; the PyPI sdist has
#                  the two test files but neither generic.py nor models/: take those from a
#                  checkout of the same era).
#   --both         gridtrace also in the place of trimesh's numpy engine (ray_triangle), so the
#                  tests that ask for it by name run on gridtrace too.
#
# The Python (PYTHON, default python3) needs pytest, numpy, gridtrace importable, and:
# open3d (open3d-cpu) for --open3d; trimesh, rtree, scipy and manifold3d (trimesh's boolean
# backend, for test_contains_cavity) for --trimesh. Exit status: non-zero if any run fails.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
python="${PYTHON:-python3}"
open3d_file="" trimesh_dir="" both=0
while [ $# -gt 0 ]; do
    case "$1" in
        --open3d) open3d_file="$2"; shift 2 ;;
        --trimesh) trimesh_dir="$2"; shift 2 ;;
        --both) both=1; shift ;;
        --) shift; break ;;
        -h|--help) sed -n '2,22p' "${BASH_SOURCE[0]}"; exit 0 ;;
        *) echo "peer_tests.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
if [ -z "$open3d_file" ] && [ -z "$trimesh_dir" ]; then
    echo "peer_tests.sh: give --open3d FILE and/or --trimesh DIR (see --help)" >&2
    exit 2
fi

export PYTHONPATH="$here/peer_shims${PYTHONPATH:+:$PYTHONPATH}"
"$python" -c 'import gridtrace, sys; print("gridtrace:", gridtrace.__file__, file=sys.stderr)'
status=0

if [ -n "$open3d_file" ]; then
    [ -f "$open3d_file" ] || { echo "peer_tests.sh: --open3d: no file '$open3d_file'" >&2; exit 2; }
    dir="$(cd "$(dirname "$open3d_file")" && pwd)"
    echo "== Open3D: $open3d_file"
    # -p no:cacheprovider: nothing is written into the peers' folders.
    (cd "$dir" && "$python" -m pytest -p gridtrace_open3d_shim -p no:cacheprovider -rfE \
        "$(basename "$open3d_file")" "$@") || status=1
fi

if [ -n "$trimesh_dir" ]; then
    for f in test_ray.py test_ray_upstream.py generic.py; do
        [ -f "$trimesh_dir/$f" ] || { echo "peer_tests.sh: --trimesh: no $f in '$trimesh_dir'" >&2; exit 2; }
    done
    echo "== trimesh: $trimesh_dir/test_ray.py, test_ray_upstream.py"
    engines=embree
    [ "$both" = 1 ] && engines=both
    (cd "$trimesh_dir" && GRIDTRACE_SHIM_ENGINES="$engines" "$python" -m pytest -p gridtrace_trimesh_shim \
        -p no:cacheprovider -rfE test_ray.py test_ray_upstream.py "$@") || status=1
fi

exit "$status"
