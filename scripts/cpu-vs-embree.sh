#!/usr/bin/env bash
# The CPU BVH's ray batches beside Embree 3 on the same rays, at several thread counts, measured
# alternating (Embree, then gridtrace, REPS times per thread count), as ratios.
#
#   scripts/cpu-vs-embree.sh MESH GRIDTRACE EMBREE_RAYS "1 2 4 8 16" [REPS] > table.md
#
# Ray sets (written to $WORK, default /tmp/cpu-vs-embree): `eye` (a 512x512 camera's eye rays,
# Embree's default camera), `camera` (the same at 1024x1024: 1M rays in image order) and
# `random` (1M incoherent rays: make_random_rays.py beside EMBREE_RAYS, else a numpy-free
# inline generator with the same recipe). Both tools report their tracing rate alone (no file
# reading, no build): Embree's `rayfile.mrays_per_s` (the median of its --reps 3), gridtrace
# `rays`' `Mrays/s` (the median of its --reps 3, `--backend cpu --accel bvh`): warm passes
# both. Each row gives the best of the REPS alternating runs of each, and ratio = gridtrace /
# Embree (above 1: gridtrace faster).
# The closing rows give gridtrace's scaling: its rate at N threads over its rate at the first.
# Embree's library and its TBB/OpenMP come from LD_LIBRARY_PATH (scripts/gpu-run.sh sets it).
set -u
mesh=$1; gt=$2; emb=$3; threads=${4:-"1 2"}; reps=${5:-3}
work=${WORK:-/tmp/cpu-vs-embree}; mkdir -p "$work"
here=$(dirname "$emb")
[ -s "$work/eye.bin" ] || "$emb" "$mesh" --res 512x512 --dump-rays "$work/eye.bin" --reps 1 >/dev/null 2>&1
[ -s "$work/camera.bin" ] || "$emb" "$mesh" --res 1024x1024 --dump-rays "$work/camera.bin" --reps 1 >/dev/null 2>&1
[ -s "$work/random.bin" ] || python3 "$here/make_random_rays.py" "$mesh" "$work/random.bin" 1000000 5 >/dev/null
embree() { # threads rays -> Mrays/s
  "$emb" "$mesh" --rays "$2" --threads "$1" --reps 3 --hits-out "$work/emb.t" 2>/dev/null | tail -1 |
    python3 -c "import json,sys; print(json.load(sys.stdin)['rayfile']['mrays_per_s'])" 2>/dev/null || echo nan
}
ours() { # threads rays -> Mrays/s
  "$gt" rays "$mesh" --rays "$2" --threads "$1" --reps 3 --backend cpu --accel bvh --hits-out "$work/gt.bin" 2>/dev/null |
    sed -n 's/^rays .* \([0-9.]*\) Mrays\/s$/\1/p' | head -1 | grep . || echo nan
}
best() { tr ' ' '\n' | grep -v nan | sort -g | tail -1 | grep . || echo nan; }
echo "cpu: $(nproc) cores, $(lscpu | sed -n 's/^Model name: *//p'); $(grep -o -w 'avx2\|avx512f' /proc/cpuinfo | sort -u | tr '\n' ' ')"
echo "gridtrace: $("$gt" --version 2>&1 | tr '\n' ' ')"
echo
echo "| rays | threads | Embree 3 Mrays/s (best of $reps) | gridtrace bvh Mrays/s (best of $reps) | gridtrace / Embree | all runs (Embree; gridtrace) |"
echo "|---|---|---|---|---|---|"
declare -A first
for set in eye camera random; do
  for t in $threads; do
    es=""; gs=""
    for _ in $(seq "$reps"); do es="$es $(embree "$t" "$work/$set.bin")"; gs="$gs $(ours "$t" "$work/$set.bin")"; done
    e=$(echo $es | best); g=$(echo $gs | best)
    r=$(python3 -c "print(f'{$g / $e:.2f}')" 2>/dev/null || echo nan)
    echo "| $set | $t | $e | $g | $r | $es;$gs |"
    [ -n "${first[$set]:-}" ] || first[$set]=$g
    echo "$set $t $g ${first[$set]}" >> "$work/scaling.txt.$$"
  done
done
echo
echo "| rays | threads | gridtrace speed-up over the first thread count |"
echo "|---|---|---|"
while read -r set t g f; do
  echo "| $set | $t | $(python3 -c "print(f'{$g / $f:.2f}')" 2>/dev/null || echo nan) |"
done < "$work/scaling.txt.$$"
rm -f "$work/scaling.txt.$$"
