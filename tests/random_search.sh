#!/usr/bin/env bash
# The random search behind the property tests. A normal run (CI, the README's test command)
# draws every property test's cases from one fixed seed and never writes the committed
# regression files (tests/common/shared.rs, `proptest_config`), so it gives the
# same answer on every run. This script is the search for new failures: it runs the
# property tests (tests/ and the unit tests) from random seeds with VTZ_PROPTEST_SCALE
# (default 8) times their cases, round after round, for MINUTES minutes (default 10). A
# failure's seed is appended to the test's regression file (tests/proptest-regressions/NAME.txt
# for tests/suite/NAME.rs, or proptest-regressions/ for a unit test), which CI then replays;
# commit it, and the shrunk input printed in the log as a plain #[test] beside the property
# test.
#
#   tests/random_search.sh [MINUTES]        # log in target/random_search.log
set -uo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-10}
export VTZ_PROPTEST_RANDOM=1
export VTZ_PROPTEST_SCALE=${VTZ_PROPTEST_SCALE:-8}
export CARGO_PROFILE_CI_INCREMENTAL=${CARGO_PROFILE_CI_INCREMENTAL:-true}
log=target/random_search.log
mkdir -p target && : > "$log"

# The property tests: the functions inside `proptest! { … }` blocks, by file.
names() {
  awk '/proptest! \{/ { inb = 1; match($0, /^ */); ind = RLENGTH; next }
       inb && match($0, /fn [a-z0-9_]+\(/) { print substr($0, RSTART + 3, RLENGTH - 4) }
       inb && match($0, /^ *\}/) && RLENGTH == ind + 1 { inb = 0 }' "$1"
}
# The integration tests are one binary, tests/suite (a module per file).
declare -a targets filters
for f in tests/suite/*.rs; do
  n=$(names "$f" | tr '\n' ' ')
  [ -n "$n" ] && targets=("--test" "suite") && filters+=($n)
done
lib=$(for f in $(grep -rl 'proptest! {' src); do names "$f"; done | tr '\n' ' ')
filters+=($lib)
echo "property tests: ${filters[*]}" | tee -a "$log"
cargo test --profile ci --lib "${targets[@]}" --no-run 2>&1 | tail -1 | tee -a "$log"

end=$((SECONDS + minutes * 60))
round=0
failed=0
while [ "$SECONDS" -lt "$end" ]; do
  round=$((round + 1))
  echo "== round $round ($(date -u +%T))" | tee -a "$log"
  if ! cargo test --profile ci -q --lib "${targets[@]}" -- "${filters[@]}" >>"$log" 2>&1; then
    failed=$((failed + 1))
    echo "   a failure (see $log)" | tee -a "$log"
  fi
done
echo "$round rounds, $failed with a failure; regression files changed:" | tee -a "$log"
git status --short -- tests/proptest-regressions proptest-regressions | tee -a "$log"
[ "$failed" -eq 0 ]
