#!/usr/bin/env bash
# The run a session makes when it is lent a GPU machine (NVIDIA H100/H200; see
# ../shared/tools/device-vulkan.md). Here: `../shared/tools/device-prep.sh`, then
# `cp scripts/gpu-run.sh .device/run.sh`, then compress the binary so that the working tree and
# .device stay under the transfer's 64 MiB (`xz -6 .device/gridtrace`, which leaves
# .device/gridtrace.xz), `cp scripts/cpu-vs-embree.sh .device/` (step 2b), then the device
# tool's `run` with carry [".device"], command
# `bash .device/run.sh` and timeout_s 600. Every step starts only while the deadline allows
# (DEADLINE seconds, default 565), so the results of the steps that ran come back.
#
# The steps, most important first: the hardware suite (every structure x GPU variant, ray
# batches, grid builds; hardware.md/json), 1M-ray batches beside Embree 3 on the same rays
# (rays.txt), the CPU BVH's scaling at 1-16 threads beside Embree (cpu-scaling.md), the paper
# matrix on the GPU and the CPU cores (paper.md/json), a 1080p camera orbit one frame at a time
# and with two frames in flight, an animated mesh, and 1,000 moving instances on each
# structure's two levels (summary.txt). The ray batches' lines give the bytes a ray each way and the host's phases
# (prepare, wait, readout) of the pipelined chunks. The first H200 runs (2026-11-26) used it; their
# output is under docs/results/h200-2026-11-26*. LOCAL=1 QUICK=1 runs it on this machine's
# lavapipe for a check of the script (no packages unpacked, the suite's --quick plan).
set -u
cd "$(dirname "$0")"
T0=$(date +%s); DEADLINE=${DEADLINE:-565}
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)} RUST_BACKTRACE=1
out=${OUT:-/tmp/gpu-bench-out}; mkdir -p "$out"
log=$out/summary.txt; : > "$log"
say() { echo "$*" | tee -a "$log"; }
[ -n "${LOCAL:-}" ] || { for f in gl/*.deb; do dpkg -x "$f" / 2>/dev/null; done; ldconfig; }
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$icd" ] && export VK_DRIVER_FILES=$icd
[ -f /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json ] && \
  export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
mkdir -p /tmp/emb && xz -dc libembree3.so.3.xz > /tmp/emb/libembree3.so.3 && \
  cp libtbb.so.12 libgomp.so.1 /tmp/emb/ 2>/dev/null
export LD_LIBRARY_PATH=/tmp/emb${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
[ -f gridtrace ] || xz -dc gridtrace.xz > gridtrace; B=$PWD/gridtrace; M=$PWD/meshes; export GRIDTRACE_DATA_DIR=$M
chmod +x "$B" embree_rays 2>/dev/null

say "== machine ($(date -u))"; nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm,clocks.mem,memory.total,power.limit --format=csv 2>&1 | tee -a "$log"
say "cpu: $(nproc) cores, $(lscpu | sed -n 's/^Model name: *//p')"
say "gridtrace: $($B --version 2>&1)"
say "== adapter check (cast, built-in scene, 64x64)"
timeout 60 $B render --scene knot-box --mode cast --res 64x64 --backend gpu -o /tmp/probe.png 2>&1 | tee -a "$log" | head -20
grep -qi 'llvmpipe\|lavapipe\|software' "$log" && say "WARNING: a software adapter was chosen; GPU figures below are not GPU figures"

say "== 5 (first). hardware suite: structures x GPU variants, rays, builds [t=$(( $(date +%s)-T0 ))s]"
timeout 295 $B bench --suite hardware ${QUICK:+--quick} --backend gpu --out /tmp/suite >/tmp/suite.log 2>&1; say "suite exit $?"
tail -25 /tmp/suite.log | tee -a "$log"
cp /tmp/suite/*.json /tmp/suite/*.md "$out/" 2>/dev/null; cp /tmp/suite.log "$out/suite.log"

say "== 2. ray queries, 1M rays, beside Embree [t=$(( $(date +%s)-T0 ))s, left $(left)s]"
r=$out/rays.txt; : > "$r"
for mesh in bunny/bun_zipper.ply dragon/dragon_vrip_binary.ply; do
  [ "$(left)" -gt 150 ] || { say "rays of $mesh skipped: deadline"; continue; }
  name=$(basename "$mesh" .ply)
  python3 make_random_rays.py "$M/$mesh" /tmp/$name-random.bin 1000000 5 >/dev/null
  ./embree_rays "$M/$mesh" --res 1024x1024 --dump-rays /tmp/$name-camera.bin --reps 1 >/dev/null 2>&1
  for set in random camera; do
    rays=/tmp/$name-$set.bin; [ -f "$rays" ] || continue
    e=$(timeout 40 ./embree_rays "$M/$mesh" --rays "$rays" --hits-out /tmp/emb.t --reps 5 2>/dev/null | tail -1 | python3 -c "import json,sys; print(json.load(sys.stdin)['rayfile']['mrays_per_s'], 'Mrays/s')" 2>&1)
    echo "$name $set embree($(nproc) threads): $e" >> "$r"
    for be in gpu cpu; do for accel in pc bvh irregular; do
      line=$(timeout 40 $B rays "$M/$mesh" --rays "$rays" --accel $accel --backend $be --hits-out /tmp/gt.bin 2>&1 | grep -iE '^rays|^gpu|^bus|^host|^error' | grep -v XDG_RUNTIME | head -5 | tr '\n' ' ')
      echo "$name $set $be $accel: $line" >> "$r"
    done; done
    # The lean answers (issue 41): (t, triangle) 8 bytes a ray down, occlusion one bit.
    for ask in --no-uv --occluded; do
      line=$(timeout 40 $B rays "$M/$mesh" --rays "$rays" --accel bvh --backend gpu $ask --hits-out /tmp/gt.bin 2>&1 | grep -iE '^rays|^gpu|^bus|^host|^error' | grep -v XDG_RUNTIME | head -5 | tr '\n' ' ')
      echo "$name $set gpu bvh $ask: $line" >> "$r"
    done
  done
done
cat "$r" >> "$log"

say "== 2b. CPU BVH beside Embree 3 at 1-16 threads (eye 512x512, camera 1M, random 1M; Bunny) [left $(left)s]"
if [ -f cpu-vs-embree.sh ] && [ "$(left)" -gt 200 ]; then
  ths="1 2 4 8 16"; reps=2; [ -n "${QUICK:-}" ] && { ths="1 2"; reps=1; }
  WORK=/tmp/cve timeout $(( $(left) - 150 )) bash cpu-vs-embree.sh "$M/bunny/bun_zipper.ply" "$B" "$PWD/embree_rays" "$ths" $reps \
    > "$out/cpu-scaling.md" 2>&1; say "cpu-vs-embree exit $?"
  cat "$out/cpu-scaling.md" >> "$log"
else
  say "skipped: no cpu-vs-embree.sh beside the run script, or the deadline"
fi

l=$(left); say "== 1. paper matrix, GPU and CPU [left ${l}s]"
if [ "$l" -gt 70 ]; then
  timeout $(( l - 50 )) $B bench --backend both --accel grid,pc,bvh,irregular --res 1024 --warmup 2 --reps 5 --out /tmp/paper >/tmp/paper.log 2>&1; say "paper exit $?"
  cp /tmp/paper/bench.md "$out/paper.md" 2>/dev/null; cp /tmp/paper/bench.json "$out/paper.json" 2>/dev/null
  tail -30 /tmp/paper.log >> "$log"
fi
say "== 3. headless camera path [left $(left)s]"
cam="--mesh $M/bunny/bun_zipper.ply --res 1920x1080 --backend gpu"
# Frames in flight (issue 41): one by one, then two in flight; `rate` is the throughput
# (frames/s and Mrays/s of wall time after the first frame), `frames` each frame's latency.
for m in cast shadow trace; do for fl in 1 2; do
  [ "$(left)" -gt 20 ] || break
  timeout 15 $B render $cam --mode $m --frames 60 --orbit --in-flight $fl -o /tmp/orbit.png 2>&1 | grep -E '^(first|frames|gpu|stages|rates|rate|render|error|Error)' | sed "s/^/$m in-flight=$fl: /" | tee -a "$log"
done; done
for rb in "" "--readback"; do for fl in 1 2; do
  [ "$(left)" -gt 20 ] || break
  timeout 15 $B view --headless $cam --mode shadow --frames 60 --orbit --in-flight $fl $rb 2>&1 | grep -E '^(image|first|rest|gpu|rate|error|Error)' | sed "s/^/view shadow in-flight=$fl $rb: /" | tee -a "$log"
done; done
say "== 4. animated mesh, grid rebuilt on the GPU every frame [left $(left)s]"
[ "$(left)" -gt 15 ] && timeout 12 $B render --animate --scene animated --frames 30 --mode shadow --accel pc --backend gpu --res 1024x1024 -o /tmp/anim.png 2>&1 | tail -3 | tee -a "$log"
say "== 4b. moving instances (issue 52): 1,000 tumbling Bunnies, 1080p eye rays, each structure's two levels [left $(left)s]"
# hwrt walks the driver's instances (one BLAS, a TLAS rebuilt a move); the others the software
# top level over each mesh's own walk. Per frame: the move, the trace (with the top level's
# upload), and the bytes a move uploads.
for accel in hwrt bvh pc irregular; do
  [ "$(left)" -gt 25 ] || break
  timeout 20 $B render --animate --scene tumbling-bunnies --frames 30 --mode cast --res 1920x1080 --backend gpu --accel $accel -o /tmp/tumble.png 2>&1 | grep -E '^(median|gpu|error|Error)' | sed "s/^/tumbling gpu $accel: /" | tee -a "$log"
done
[ "$(left)" -gt 25 ] && timeout 20 $B render --animate --scene tumbling-bunnies --frames 10 --mode cast --res 1920x1080 --backend cpu --accel bvh -o /tmp/tumble.png 2>&1 | grep -E '^(median|error|Error)' | sed "s/^/tumbling cpu bvh: /" | tee -a "$log"
say "== done [t=$(( $(date +%s)-T0 ))s]"
