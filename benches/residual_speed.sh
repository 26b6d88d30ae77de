#!/bin/bash
# Speed of the residual layer against its peers on the same files, one run after the other:
# vtz's lane coding (effort 1), fast coding (effort 2) and range coding (effort 5, the
# default) on one thread, the lane coding on two, then SZ3, LERC, JPEG XL and pcodec through
# the peers harness.
# Prints a Markdown table (benches/README.md, "the fast coding").
#
#   benches/residual_speed.sh PEERS_PYTHON FILE.f32...      (e.g. ../shared/tools/peers/.venv/bin/python)
set -euo pipefail
py=$1; shift
root=$(cd "$(dirname "$0")/.." && pwd)
cargo build --release --example residual_speed -q --manifest-path "$root/Cargo.toml"
x=$root/target/release/examples/residual_speed
out=$(mktemp -d)
for f in "$@"; do
  for b in lossless 1 1%; do
    for e in 1 2 5; do echo "T1 $(RAYON_NUM_THREADS=1 $x "$f" $b $e 3)"; done
    echo "T2 $(RAYON_NUM_THREADS=2 $x "$f" $b 1 3)"
  done
done > "$out/vtz.txt"
(cd "$root/../shared/tools/peers" && "$py" peers.py "$@" --codecs sz3,lerc,jxl,pcodec --repeat 3 --abs 1 --pct 1 --csv "$out/peers.csv" > "$out/peers.log" 2>&1)
python3 "$root/benches/residual_speed_table.py" "$out/vtz.txt" "$out/peers.csv"
