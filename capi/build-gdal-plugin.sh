#!/usr/bin/env bash
# Build the GDAL raster driver plugin gdal_VTZ.so into target/gdal-plugin/ (under the
# repository root): the C ABI (capi/, linked statically) plus the C++ shim
# capi/gdal/vtzdataset.cpp and vtzzarr.cpp, compiled against the system's GDAL (below). The plugin needs nothing at run time but
# libgdal and the C/C++ runtime.
#
#   capi/build-gdal-plugin.sh            # then:
#   export GDAL_DRIVER_PATH=$PWD/target/gdal-plugin
#   gdalinfo file.vtz
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
out="$root/target/gdal-plugin"

# GDAL's headers and library. gdal-config (libgdal-dev) when present; else, where GDAL's
# library is installed (gdal-bin brings it), Debian's libgdal-dev package unpacked for its
# headers alone (without its ~80 dependencies); else libgdal-dev installed with apt-get.
# VTZ_GDAL_HEADERS_ONLY=1 takes the unpacked headers even where gdal-config exists.
# (awk reads all of ldconfig's list: leaving early would kill ldconfig with SIGPIPE, which
# pipefail turns into a silent exit of this script.)
libgdal="$(ldconfig -p 2>/dev/null | awk '/libgdal\.so\.[0-9]+ / && !found {print $NF; found = 1}')"
if command -v gdal-config >/dev/null 2>&1 && [ -z "${VTZ_GDAL_HEADERS_ONLY:-}" ]; then
    gdal_cflags="$(gdal-config --cflags)"
    gdal_libs="$(gdal-config --libs)"
    gdal_version="$(gdal-config --version)"
elif [ -n "$libgdal" ] && command -v apt-get >/dev/null 2>&1; then
    dev="$root/target/gdal-dev"
    if [ ! -f "$dev/usr/include/gdal/gdal_priv.h" ]; then
        echo "unpacking Debian's libgdal-dev for GDAL's headers (into $dev)" >&2
        tmp="$(mktemp -d)"
        # A machine whose package lists were never fetched needs them first.
        (cd "$tmp" && apt-get download -q libgdal-dev >/dev/null 2>&1) ||
            { apt-get update -qq && (cd "$tmp" && apt-get download -q libgdal-dev >/dev/null); }
        rm -rf "$dev"
        dpkg -x "$tmp"/libgdal-dev_*.deb "$dev"
        rm -rf "$tmp"
    fi
    gdal_cflags="-I$dev/usr/include/gdal"
    gdal_libs="$libgdal"
    gdal_version="$(basename "$libgdal"), headers of Debian's libgdal-dev"
else
    echo "gdal-config not found: installing libgdal-dev (and g++) from the distribution" >&2
    sudo_cmd=()
    if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends libgdal-dev g++
    gdal_cflags="$(gdal-config --cflags)"
    gdal_libs="$(gdal-config --libs)"
    gdal_version="$(gdal-config --version)"
fi

# The C ABI's static library: VTZ_CAPI_LIB when given (CI: the one `cargo test --profile
# ci` built), else a release build of the C ABI alone.
lib="${VTZ_CAPI_LIB:-}"
if [ -z "$lib" ]; then
    echo "building the C ABI (cargo build --release -p vtz-capi)" >&2
    cargo build --release --manifest-path "$here/Cargo.toml"
    target_dir="$(cargo metadata --format-version 1 --no-deps --manifest-path "$here/Cargo.toml" |
        python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')"
    lib="$target_dir/release/libvtz_capi.a"
fi
[ -f "$lib" ] || { echo "error: $lib was not built" >&2; exit 1; }

mkdir -p "$out"
CXX="${CXX:-g++}"
echo "compiling $out/gdal_VTZ.so against GDAL $gdal_version" >&2
# shellcheck disable=SC2086  # GDAL's flags are meant to be split
"$CXX" -std=c++17 -O2 -g0 -fPIC -shared -Wall -Wextra \
    -fvisibility=hidden \
    $gdal_cflags -I"$here/include" \
    "$here/gdal/vtzdataset.cpp" "$here/gdal/vtzzarr.cpp" \
    -o "$out/gdal_VTZ.so.tmp" \
    -Wl,--no-undefined -Wl,--gc-sections -Wl,--strip-debug -Wl,--exclude-libs,ALL \
    "$lib" \
    $gdal_libs -lpthread -ldl -lm -lrt -lgcc_s
mv -f "$out/gdal_VTZ.so.tmp" "$out/gdal_VTZ.so"

echo "built $out/gdal_VTZ.so ($(du -h "$out/gdal_VTZ.so" | cut -f1))" >&2
echo "GDAL_DRIVER_PATH=$out"
