#!/usr/bin/env bash
# Third H200 run of 2026-11-26: the hardware suite again with the host's phases per frame and
# batch and the variants timed in rounds; then 1M-ray batches and 1080p frames through the CLI.
set -u
cd "$(dirname "$0")"
T0=$(date +%s); DEADLINE=${DEADLINE:-225}
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)} RUST_BACKTRACE=1
out=${OUT:-/tmp/gpu-bench-out}; mkdir -p "$out"
log=$out/summary.txt; : > "$log"
say() { echo "$*" | tee -a "$log"; }
[ -n "${LOCAL:-}" ] || { for f in gl/*.deb; do dpkg -x "$f" / 2>/dev/null; done; ldconfig; }
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$icd" ] && export VK_DRIVER_FILES=$icd
[ -f gridtrace ] || xz -dc gridtrace.xz > gridtrace; B=$PWD/gridtrace; M=$PWD/meshes; export GRIDTRACE_DATA_DIR=$M
chmod +x "$B"
say "== machine ($(date -u))"; nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm,clocks.mem,memory.total,power.limit --format=csv 2>&1 | tee -a "$log"
say "gridtrace: $($B --version 2>&1 | head -1)"
say "== hardware suite [t=$(( $(date +%s)-T0 ))s]"
timeout 200 $B bench --suite hardware ${QUICK:+--quick} --backend gpu --out /tmp/suite >/tmp/suite.log 2>&1; say "suite exit $?"
tail -8 /tmp/suite.log | tee -a "$log"
cp /tmp/suite/*.json /tmp/suite/*.md "$out/" 2>/dev/null; cp /tmp/suite.log "$out/suite.log"
say "== 1080p orbit: default and the candidate [left $(left)s]"
for v in bvh=binary stack=short,order=tiles,appends=workgroup,stats=off; do for m in cast trace; do
  [ "$(left)" -gt 10 ] || break
  timeout 10 $B render --mesh $M/bunny/bun_zipper.ply --res 1920x1080 --backend gpu --mode $m --frames 60 --orbit --gpu-variant $v -o /tmp/orbit.png 2>&1 | grep -E '^(frames|gpu|host|error)' | sed "s/^/$m $v: /" | tee -a "$log"
done; done
say "== done [t=$(( $(date +%s)-T0 ))s]"
