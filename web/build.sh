#!/bin/sh
# Build vtz's browser decoder: web/wasm (a cdylib over vtz with default features off) for
# wasm32-unknown-unknown, then web/dist/vtz.wasm.
#
# Toolchain: Debian's Rust 1.96 with its std source, built with -Zbuild-std (there is no
# prebuilt wasm32 std for it), and lld for the link; binaryen for wasm-opt/wasm-metadce:
#   apt-get install -y rustc-web cargo-web rust-web-src lld-22 binaryen
# The compiler must be the one that matches the std source exactly, so this uses
# /usr/bin/rustc and /usr/bin/cargo, not rustup's (override with VTZ_WASM_CARGO/RUSTC).
#
# Environment: JOBS (cargo -j; default: every core), VTZ_WASM_SIMD=0 (build without
# +simd128), VTZ_WASM_TARGET_DIR (default $CARGO_TARGET_DIR/wasm when CARGO_TARGET_DIR is
# set, else web/wasm/target: never the host's own target directory, whose compiler differs),
# VTZ_WASM_OUT (default web/dist/vtz.wasm), CARGO_PROFILE_RELEASE_* (profile experiments;
# the defaults are in wasm/Cargo.toml).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
cargo=${VTZ_WASM_CARGO:-/usr/bin/cargo}
export RUSTC="${VTZ_WASM_RUSTC:-/usr/bin/rustc}"
export RUSTDOC="${RUSTDOC:-/usr/bin/rustdoc}"
# -Zbuild-std on a stable compiler.
export RUSTC_BOOTSTRAP=1
# 128-bit SIMD (Node 16.4+, Chrome 91+, Firefox 89+, Safari 16.4+): the residual layer's
# lane coding decodes 1.4-2x faster with it (web/README.md).
flags="${RUSTFLAGS:-}"
if [ "${VTZ_WASM_SIMD:-1}" = 1 ]; then
    flags="$flags -C target-feature=+simd128"
fi
export CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUSTFLAGS="$flags"
if [ -n "${VTZ_WASM_TARGET_DIR:-}" ]; then
    target_dir=$VTZ_WASM_TARGET_DIR
elif [ -n "${CARGO_TARGET_DIR:-}" ]; then
    target_dir=$CARGO_TARGET_DIR/wasm
else
    target_dir=$here/wasm/target
fi
unset CARGO_TARGET_DIR

start=$(date +%s)
"$cargo" build ${JOBS:+-j "$JOBS"} --release \
    --manifest-path "$here/wasm/Cargo.toml" --target-dir "$target_dir" \
    --target wasm32-unknown-unknown -Zbuild-std=std,panic_abort
echo "build.sh: cargo build took $(( $(date +%s) - start )) s" >&2

mkdir -p "$(dirname "${VTZ_WASM_OUT:-$here/dist/vtz.wasm}")"
raw="$target_dir/wasm32-unknown-unknown/release/vtz_wasm.wasm"
out=${VTZ_WASM_OUT:-$here/dist/vtz.wasm}
if command -v wasm-metadce >/dev/null 2>&1 && command -v wasm-opt >/dev/null 2>&1 && command -v node >/dev/null 2>&1; then
    # las's chrono (default feature wasmbind) drags in wasm-bindgen, whose ~2,500
    # __wbindgen_describe_* exports and __wbindgen_placeholder__ imports vtz never uses:
    # keep only vtz_* and memory as roots, so they and the imports go.
    graph="$out.roots.json"
    node -e '
      const fs = require("fs");
      const m = new WebAssembly.Module(fs.readFileSync(process.argv[1]));
      const roots = WebAssembly.Module.exports(m)
        .filter((e) => e.name.startsWith("vtz_") || e.name === "memory")
        .map((e) => ({ name: e.name, root: true, export: e.name }));
      fs.writeFileSync(process.argv[2], JSON.stringify(roots));
    ' "$raw" "$graph"
    wasm-metadce "$raw" -f "$graph" -o "$out.tmp" >/dev/null
    rm -f "$graph"
    # -O1: as fast to decode as -O3 in V8 (which optimises the code again) and smaller once
    # gzipped, in 4 s instead of 45 s of CPU (web/README.md).
    wasm-opt -O1 --strip-debug --strip-producers "$out.tmp" -o "$out"
    rm -f "$out.tmp"
else
    echo "build.sh: wasm-opt, wasm-metadce (apt-get install binaryen) or node not found: copying the raw module" >&2
    cp "$raw" "$out"
fi
echo "build.sh: $out $(wc -c <"$out") bytes (raw $(wc -c <"$raw")) after $(( $(date +%s) - start )) s" >&2
