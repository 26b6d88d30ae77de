#!/usr/bin/env bash
# Build the GDAL raster driver plugin gdal_VTZ.so into target/gdal-plugin/ (under the
# repository root): the C ABI (capi/, linked statically) plus the C++ shim
# capi/gdal/vtzdataset.cpp, compiled against the system's GDAL (libgdal-dev, installed
# with apt-get when gdal-config is absent). The plugin needs nothing at run time but
# libgdal and the C/C++ runtime.
#
#   capi/build-gdal-plugin.sh            # then:
#   export GDAL_DRIVER_PATH=$PWD/target/gdal-plugin
#   gdalinfo file.vtz
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
out="$root/target/gdal-plugin"

if ! command -v gdal-config >/dev/null 2>&1; then
    echo "gdal-config not found: installing libgdal-dev (and g++) from the distribution" >&2
    sudo_cmd=()
    if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends libgdal-dev g++
fi

echo "building the C ABI (cargo build --release in capi/)" >&2
cargo build --release --manifest-path "$here/Cargo.toml"
# The crate may be its own workspace or a member of the repository's: ask cargo where
# its target directory is.
target_dir="$(cargo metadata --format-version 1 --no-deps --manifest-path "$here/Cargo.toml" |
    python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')"
lib="$target_dir/release/libvtz_capi.a"
[ -f "$lib" ] || { echo "error: $lib was not built" >&2; exit 1; }

mkdir -p "$out"
CXX="${CXX:-g++}"
echo "compiling $out/gdal_VTZ.so against GDAL $(gdal-config --version)" >&2
# shellcheck disable=SC2046  # gdal-config's flags are meant to be split
"$CXX" -std=c++17 -O2 -g0 -fPIC -shared -Wall -Wextra \
    -fvisibility=hidden \
    $(gdal-config --cflags) -I"$here/include" \
    "$here/gdal/vtzdataset.cpp" \
    -o "$out/gdal_VTZ.so.tmp" \
    -Wl,--no-undefined -Wl,--gc-sections -Wl,--strip-debug -Wl,--exclude-libs,ALL \
    "$lib" \
    $(gdal-config --libs) -lpthread -ldl -lm -lrt -lgcc_s
mv -f "$out/gdal_VTZ.so.tmp" "$out/gdal_VTZ.so"

echo "built $out/gdal_VTZ.so ($(du -h "$out/gdal_VTZ.so" | cut -f1))" >&2
echo "GDAL_DRIVER_PATH=$out"
