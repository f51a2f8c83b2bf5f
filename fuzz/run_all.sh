#!/bin/sh
# Runs every fuzz target for $1 seconds (default 600), one after another, from the binaries
# `cargo +nightly fuzz build -O` left (no rebuild between targets). TARGETS="a b" picks some;
# several copies may run at once (each target logs to logs/TARGET.log). New inputs go to
# corpus-raw/TARGET (ignored); the committed corpus/TARGET (reduced with -set_cover_merge=1) seeds.
T=${1:-600}
cd "$(dirname "$0")"
BIN=target/x86_64-unknown-linux-gnu/release
mkdir -p logs artifacts
for t in ${TARGETS:-traverse obj ply gltf scene_file}; do
  echo "=== $t $(date)"
  mkdir -p artifacts/$t corpus-raw/$t
  $BIN/$t corpus-raw/$t corpus/$t -max_total_time=$T -max_len=4096 -rss_limit_mb=2048 -timeout=10 \
    -artifact_prefix=artifacts/$t/ -print_final_stats=1 > logs/$t.log 2>&1
  echo "=== $t exit $? $(date)"
done
