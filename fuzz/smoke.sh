#!/usr/bin/env bash
# The coverage-guided search as a smoke run: each fuzz target for SECONDS (default 8) from the
# seeds of make_seeds.py, built without AddressSanitizer and debug info (quicker to build; the
# long runs of fuzz/README.md keep ASan). Random by nature, so it runs before a stop, not in
# CI (CI replays every seed deterministically: tests/suite/fuzz_seeds.rs). Fails on any artifact.
#   fuzz/smoke.sh [SECONDS] [path/to/vtz]
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-8}"
vtz="${2:-target/ci/vtz}"
command -v cargo-fuzz >/dev/null 2>&1 || cargo install cargo-fuzz --locked -q
python3 fuzz/make_seeds.py "$vtz" >/dev/null
for t in container sections readers roundtrip points; do
  echo "-- fuzz $t ($secs s)"
  (cd fuzz && CARGO_PROFILE_RELEASE_DEBUG=0 cargo +nightly fuzz run -s none "$t" "corpus/$t" -- -max_total_time="$secs" \
    -rss_limit_mb=2048 -print_final_stats=1 2>&1 | grep -E '^(stat::number_of_executed_units|stat::peak_rss_mb|#[0-9]+ *DONE)|ERROR|panicked' || true)
  if [ -n "$(ls -A "fuzz/artifacts/$t" 2>/dev/null)" ]; then
    echo "fuzz target $t found a crash: fuzz/artifacts/$t" >&2
    exit 1
  fi
done
echo "fuzz smoke: no crash"
