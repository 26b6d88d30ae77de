#!/usr/bin/env bash
# Builds everything benches/remote/run.sh measures from this checkout, then runs it: the CLI
# and C ABI (the ci profile, as .ci/run builds them), the GDAL plugin
# (capi/build-gdal-plugin.sh), and the Python package (maturin, into a venv of its own under
# target/), so that every `.vtz` row is this checkout's code.
#
#   benches/remote/build_and_run.sh DATA_DIR [RUNS]
#
# VTZ_BENCH_VENV (default target/remote-bench-venv) is the venv the wheel goes into.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
[ $# -ge 1 ] || { echo "usage: $0 DATA_DIR [RUNS]" >&2; exit 2; }
target="${CARGO_TARGET_DIR:-target}"

echo "== cargo build --profile ci --lib --bins --tests" >&2
cargo build --profile ci --lib --bins --tests
echo "== capi/build-gdal-plugin.sh" >&2
VTZ_CAPI_LIB="$target/ci/libvtz_capi.a" capi/build-gdal-plugin.sh >&2

venv="${VTZ_BENCH_VENV:-$root/target/remote-bench-venv}"
echo "== the Python package into $venv (maturin build --profile ci)" >&2
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q --disable-pip-version-check maturin numpy fsspec aiohttp
rm -rf "$venv/dist"
"$venv/bin/maturin" build --profile ci -q -m python/Cargo.toml -o "$venv/dist"
"$venv/bin/pip" install -q --disable-pip-version-check --force-reinstall --no-deps "$venv"/dist/vtz-*.whl

echo "== benches/remote/run.sh $*" >&2
VTZ_BIN="$target/ci/vtz" VTZ_PLUGIN_DIR="$root/target/gdal-plugin" VTZ_PYTHON="$venv/bin/python" \
  exec benches/remote/run.sh "$@"
