#!/usr/bin/env bash
# Build the C ABI and its C test program with the system's C compiler, then run it on the
# golden files. Used by .ci/run; works from any directory.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
profile="${VTZ_CAPI_PROFILE:-release}"
target="${CARGO_TARGET_DIR:-$here/../target}"
if [ -n "${VTZ_CAPI_LIB:-}" ]; then
  # A static library already built (CI passes the one `cargo build --profile ci` made).
  lib="$VTZ_CAPI_LIB"
  [ -f "$lib" ] || { echo "run-c-test: VTZ_CAPI_LIB=$lib does not exist" >&2; exit 1; }
else
  cargo build --profile "$profile" -p vtz-capi --manifest-path "$here/../Cargo.toml"
  lib="$target/$profile/libvtz_capi.a"
fi
out="$target/c-test"
mkdir -p "$out"
cc -std=c11 -Wall -Wextra -Werror -O1 -I "$here/include" "$here/tests/capi_test.c" \
  "$lib" -lpthread -ldl -lm -o "$out/capi_test"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$out/capi_test" "$here/../tests/golden" "$tmp"
