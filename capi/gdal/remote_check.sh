#!/usr/bin/env bash
# The GDAL plugin on a file served over HTTP (CI): gdalinfo, a gdal_translate -srcwin of a
# 256 x 256 window and overviews through /vsicurl/ give the local file's samples bit for bit,
# and fetch only the header, the tile index and the blocks of the tiles they touch (never the
# whole file), counted from the log of an nginx this script starts on 127.0.0.1 (byte ranges,
# one line per request: method, URI, Range header, status, body bytes).
#
#   capi/gdal/remote_check.sh VTZ_CLI PLUGIN_DIR
#
# Needs nginx (Debian's nginx-light; .ci/run installs it), gdal-bin and python3-gdal. The
# file is version 5 (header and tile index in the first 64 KB, a tile's overview K a
# prefix of its block, every block's head — the chunks of overviews at the file's split and
# coarser — before every block's tail): opening is GDAL's HEAD and the first 64 KB (two
# GETs: its first 16 KB chunk, then the rest; one with GDAL_INGESTED_BYTES_AT_OPEN=65536),
# no index read; a full-resolution window is one request per row of tiles for its tiles'
# heads and one per row for their tails (the library reads a band's tile blocks in one read_ranges
# call; GDAL merges consecutive ranges) and at most 1.5x the touched tiles' bytes; overview
# reads fetch at most the touched tiles' bytes.
set -euo pipefail

if [ $# -ne 2 ]; then
    echo "usage: $0 VTZ_CLI PLUGIN_DIR" >&2
    exit 2
fi
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
VTZ="$(cd "$(dirname "$1")" && pwd)/$(basename "$1")"
export GDAL_DRIVER_PATH="$(cd "$2" && pwd)"
[ -x "$VTZ" ] || { echo "FAIL: no vtz CLI at $VTZ" >&2; exit 1; }
[ -f "$GDAL_DRIVER_PATH/gdal_VTZ.so" ] || { echo "FAIL: no gdal_VTZ.so in $GDAL_DRIVER_PATH" >&2; exit 1; }
NGINX="$(command -v nginx || echo /usr/sbin/nginx)"
[ -x "$NGINX" ] || { echo "FAIL: no nginx (apt-get install nginx-light)" >&2; exit 1; }
PY="${PYTHON:-}"
if [ -z "$PY" ]; then
    for p in python3 /usr/bin/python3; do
        if "$p" -c 'import osgeo.gdal, numpy' 2>/dev/null; then PY="$p"; break; fi
    done
fi
[ -n "$PY" ] || { echo "FAIL: no python3 with osgeo.gdal and numpy" >&2; exit 1; }

work="$(mktemp -d)"
ngx_pid=""
cleanup() {
    if [ -n "$ngx_pid" ]; then kill "$ngx_pid" 2>/dev/null || true; wait "$ngx_pid" 2>/dev/null || true; fi
    rm -rf "$work"
}
trap cleanup EXIT
cd "$work"
mkdir -p www ngx
# nginx's worker may run as another user (nobody, when started by root): let it read www/.
chmod a+rx "$work" www
step() { echo "== $*"; }
ok() { echo "   ok: $*"; }

# What a user sets for a remote .vtz (capi/README.md, "Remote files"): no directory listing
# and no probes for .aux.xml / .ovr / .msk siblings. The /vsicurl/ chunk size stays GDAL's
# 16 KB and VSI_CACHE off (see the README for why).
export GDAL_DISABLE_READDIR_ON_OPEN=EMPTY_DIR
export CPL_VSIL_CURL_ALLOWED_EXTENSIONS=.vtz
export GDAL_PAM_ENABLED=NO
CHUNK=16384

step "inputs: Istria's SRTM1 crop (2400 x 2400, corpus/) encoded with --tile 256 --max-error 1"
"$VTZ" -q encode "$root/corpus/srtm1_N45E013_istria_crop2400.png" --png-offset -32768 \
    -o www/istria.vtz --max-error 1 --tile 256
"$VTZ" info --json www/istria.vtz >istria.json
size=$(stat -c %s www/istria.vtz)
ok "www/istria.vtz: $size bytes"

# nginx, unprivileged where possible, on a free port of 127.0.0.1, serving www/.
port="$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
cat >ngx/nginx.conf <<EOF
worker_processes 1;
daemon off;
pid $work/ngx/nginx.pid;
error_log $work/ngx/error.log;
events { worker_connections 64; }
http {
    log_format ranges '\$request_method \$uri \$http_range \$status \$body_bytes_sent';
    access_log $work/ngx/access.log ranges;
    client_body_temp_path $work/ngx/body;
    proxy_temp_path $work/ngx/proxy;
    fastcgi_temp_path $work/ngx/fastcgi;
    uwsgi_temp_path $work/ngx/uwsgi;
    scgi_temp_path $work/ngx/scgi;
    server {
        listen 127.0.0.1:$port;
        root $work/www;
        max_ranges 1024;
    }
}
EOF
"$NGINX" -p "$work/ngx" -c "$work/ngx/nginx.conf" -e "$work/ngx/error.log" &
ngx_pid=$!
# Up when a ranged GET answers (Python's urllib: no curl needed).
"$PY" - "http://127.0.0.1:$port/istria.vtz" <<'PYEOF' || { echo "FAIL: nginx did not start:" >&2; cat ngx/error.log >&2; exit 1; }
import sys, time, urllib.request
for _ in range(100):
    try:
        r = urllib.request.urlopen(urllib.request.Request(sys.argv[1], headers={"Range": "bytes=0-7"}), timeout=2)
        if r.status == 206 and r.read() == b"\x89VTZ\r\n\x1a\n":
            sys.exit(0)
    except OSError:
        pass
    time.sleep(0.1)
sys.exit(1)
PYEOF
URL="/vsicurl/http://127.0.0.1:$port/istria.vtz"
ok "nginx on 127.0.0.1:$port"

# Run a command with an empty access log, then keep the log under NAME.log.
logged() {
    local name="$1"; shift
    : >ngx/access.log
    "$@"
    sleep 0.3  # nginx writes its log line after the response
    cp ngx/access.log "$name.log"
}

cat >req.py <<'PYEOF'
import json, sys
import numpy as np
from osgeo import gdal
gdal.UseExceptions()
CHUNK = 16384
HEAD = 65536  # vtz reads the first 64 KB on opening

def fail(msg):
    print("FAIL: " + msg, file=sys.stderr)
    sys.exit(1)

def requests(log):
    """(method, start, end, status, bytes) per request; a GET without Range spans the file."""
    out = []
    for line in open(log):
        m, uri, rng, status, nbytes = line.split()
        if rng.startswith("bytes="):
            a, b = rng[6:].split("-")
            out.append((m, int(a), int(b) + 1, int(status), int(nbytes)))
        else:
            out.append((m, None, None, int(status), int(nbytes)))
    return out

def tiles(info_json):
    d = json.load(open(info_json))
    return d["tiles"]["index"]

def index_bytes(info_json, size):
    """Bytes after the last tile block (a version-2 file's tile index; 0 when it is first)."""
    t = tiles(info_json)
    end = max(max(e["offset"] + e["head_bytes"], e["tail_offset"] + e["bytes"] - e["head_bytes"]) for e in t)
    return size - end

def touched(info_json, x, y, w, h, level=0):
    """Tiles whose coded samples (the core and the 8-sample margins into its neighbours)
    meet the window (in the samples of overview `level`)."""
    s = 1 << level
    X0, Y0, X1, Y1 = x * s, y * s, (x + w) * s, (y + h) * s
    out = []
    for e in tiles(info_json):
        cx, cy, cw, ch = e["coded"]
        if cx < X1 and X0 < cx + cw and cy < Y1 and Y0 < cy + ch:
            out.append(e)
    return out

def summary(reqs):
    return f"{len(reqs)} requests, {sum(r[4] for r in reqs)} bytes"

def check_open(log, info_json, size):
    """Opening fetches the first 64 KB (in GDAL's 16 KB chunks) and the index, never more."""
    reqs = requests(log)
    idx = index_bytes(info_json, size)
    # Version 4 (what vtz writes): the header and the index are in the first 64 KB, so no
    # read of an index at the end (idx = 0): GDAL's HEAD, its first chunk, the rest.
    allowed = HEAD + CHUNK + (idx + 2 * CHUNK if idx else 0)
    n_allowed = 1 + 2 + (1 if idx else 0)  # HEAD, GDAL's first chunk, the rest of 64 KB, the index
    got = sum(r[4] for r in reqs)
    if any(r[1] is None and r[0] == "GET" for r in reqs):
        fail(f"{log}: a GET of the whole file: {reqs}")
    if got > allowed or len(reqs) > n_allowed:
        fail(f"{log}: opening took {summary(reqs)}; at most {n_allowed} requests and {allowed} bytes "
             f"(64 KB + a chunk + the {idx}-byte index + 2 chunks)")
    print(f"   open: {summary(reqs)} (at most {n_allowed} requests, {allowed} bytes; file {size})")
    return {(r[0], r[1], r[2]) for r in reqs}

def check_window(log, open_log, info_json, size, x, y, w, h, level=0, what="window"):
    """Beyond the open, a window fetches only blocks of the tiles it touches, each once."""
    opened = {(r[0], r[1], r[2]) for r in requests(open_log)}
    reqs = [r for r in requests(log) if (r[0], r[1], r[2]) not in opened]
    if any(r[1] is None for r in reqs):
        fail(f"{log}: a request without a range (the whole file): {reqs}")
    t = touched(info_json, x, y, w, h, level)
    need = sum(e["bytes"] for e in t)
    # Each fetched byte lies in a touched tile's head or tail, widened to GDAL's chunks (in
    # case a read takes /vsicurl/'s chunked path).
    def widened(a, b):
        return (a // CHUNK * CHUNK, -(-b // CHUNK) * CHUNK)
    spans = [widened(e["offset"], e["offset"] + e["head_bytes"]) for e in t]
    spans += [widened(e["tail_offset"], e["tail_offset"] + e["bytes"] - e["head_bytes"]) for e in t]
    for r in reqs:
        if not any(a <= r[1] and r[2] <= b for a, b in spans):
            fail(f"{log}: bytes {r[1]}..{r[2]} lie outside the blocks of the {len(t)} tiles the {what} touches")
    got = sum(r[4] for r in reqs)
    if got > need + 2 * CHUNK or len(reqs) > 2 * len(t):
        fail(f"{log}: the {what} took {summary(reqs)} beyond the open; its {len(t)} tiles hold {need} bytes "
             f"(at most {2 * len(t)} requests and {need + 2 * CHUNK} bytes)")
    if level == 0 and what.startswith("window"):
        # Issue 36's target: the tails of a row of tiles lie back to back and come in one
        # request, the heads of its tiles in one more (one read_ranges call per band, GDAL
        # merging consecutive ranges), and the bytes are at most 1.5x the touched tiles'.
        rows = len({e["y"] for e in t})
        if len(reqs) > 2 * rows or got > 1.5 * need:
            fail(f"{log}: the {what} took {summary(reqs)} beyond the open for {rows} rows of tiles "
                 f"holding {need} bytes (at most {2 * rows} requests and 1.5x the bytes)")
    total = sum(r[4] for r in requests(log))
    if total >= size // 2:
        fail(f"{log}: {total} bytes of a {size}-byte file")
    print(f"   {what}: {summary(reqs)} beyond the open for {len(t)} touched tiles of {need} bytes "
          f"(whole command: {summary(requests(log))}; file {size})")

def check_each_once(log, open_log, size):
    """A read of every tile fetches each byte once: beyond the open, at most the file."""
    opened = {(r[0], r[1], r[2]) for r in requests(open_log)}
    reqs = [r for r in requests(log) if (r[0], r[1], r[2]) not in opened]
    got = sum(r[4] for r in reqs)
    if got > size:
        fail(f"{log}: {summary(reqs)} beyond the open, more than the {size}-byte file")
    print(f"   every tile: {summary(reqs)} beyond the open (file {size})")

def same(a_path, b_path):
    a = gdal.Open(a_path).ReadAsArray()
    b = gdal.Open(b_path).ReadAsArray()
    if a.shape != b.shape or a.dtype != b.dtype or not np.array_equal(a, b):
        fail(f"{a_path} / {b_path}: samples differ")

def read_error(url, www_file):
    """A tile read that the server refuses (the file went away after the open) is a GDAL
    error naming the file and the cause, never a crash or made-up samples."""
    import os
    ds = gdal.Open(url)
    band = ds.GetRasterBand(1)
    os.rename(www_file, www_file + ".gone")
    try:
        band.ReadAsArray(1000, 1000, 256, 256)
    except RuntimeError as e:
        msg = str(e)
        if "vtz" not in msg or "istria.vtz" not in msg:
            fail(f"the read error does not name vtz and the file: {msg}")
        print(f"   a tile the server no longer has: {msg.splitlines()[0][:200]}")
    else:
        fail("a read of a window the server refuses succeeded")
    finally:
        os.rename(www_file + ".gone", www_file)

if __name__ == "__main__":
    cmd, a = sys.argv[1], sys.argv[2:]
    if cmd == "open": check_open(a[0], a[1], int(a[2]))
    elif cmd == "window": check_window(a[0], a[1], a[2], int(a[3]), *map(int, a[4:9]), what=a[9])
    elif cmd == "each_once": check_each_once(a[0], a[1], int(a[2]))
    elif cmd == "same": same(a[0], a[1])
    elif cmd == "read_error": read_error(a[0], a[1])
    else: fail(f"unknown helper {cmd}")
PYEOF

step "1. gdalinfo over /vsicurl/ shows what the local file shows, and fetches the header and index only"
logged open gdalinfo -json "$URL" >remote_info.json
gdalinfo -json www/istria.vtz >local_info.json
"$PY" - remote_info.json local_info.json <<'PYEOF'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
for k in ("size", "geoTransform", "coordinateSystem", "metadata"):
    if a.get(k) != b.get(k):
        sys.exit(f"FAIL: gdalinfo's {k} differs: {a.get(k)!r} / {b.get(k)!r}")
ba, bb = a["bands"][0], b["bands"][0]
for k in ("type", "noDataValue", "block", "overviews"):
    if ba.get(k) != bb.get(k):
        sys.exit(f"FAIL: gdalinfo's band {k} differs: {ba.get(k)!r} / {bb.get(k)!r}")
print(f"   the same size, georeferencing, metadata, band type, blocks and overviews as the local file")
PYEOF
"$PY" req.py open open.log istria.json "$size"

step "2. a 256 x 256 window (gdal_translate -srcwin) over /vsicurl/: the local file's samples, and only its tiles"
for win in "1000 1000" "1100 1100" "0 0" "2144 2144"; do
    set -- $win
    x=$1 y=$2
    logged "win_${x}_$y" gdal_translate -q -srcwin "$x" "$y" 256 256 "$URL" "remote_${x}_$y.tif"
    gdal_translate -q -srcwin "$x" "$y" 256 256 www/istria.vtz "local_${x}_$y.tif"
    "$VTZ" -q decode www/istria.vtz --window "$x,$y,256,256" -o "cli_${x}_$y.tif"
    "$PY" req.py same "remote_${x}_$y.tif" "local_${x}_$y.tif"
    "$PY" req.py same "remote_${x}_$y.tif" "cli_${x}_$y.tif"
    "$PY" req.py window "win_${x}_$y.log" open.log istria.json "$size" "$x" "$y" 256 256 0 "window $x,$y 256x256"
    ok "window $x,$y: bit for bit the local GDAL read and vtz decode --window"
done

step "3. overviews over /vsicurl/: -ovr and -outsize give the local file's samples; every tile fetched at most once"
logged ovr1 gdal_translate -q -ovr 1 "$URL" remote_ovr1.tif
gdal_translate -q -ovr 1 www/istria.vtz local_ovr1.tif
"$VTZ" -q decode www/istria.vtz --overview 2 -o cli_ovr2.tif
"$PY" req.py same remote_ovr1.tif local_ovr1.tif
"$PY" req.py each_once ovr1.log open.log "$size"
logged small gdal_translate -q -outsize 600 600 "$URL" remote_small.tif
"$PY" req.py same remote_small.tif cli_ovr2.tif
"$PY" req.py each_once small.log open.log "$size"
ok "overview 2 (-ovr 1) and a 600 x 600 read (overview 2: vtz decode --overview 2) bit for bit"
# A window read from overview 2 (gdal_translate's -srcwin is in full-resolution samples:
# 1000..1511, overview 2's 250..377): only the tiles holding it.
logged ovr_win gdal_translate -q -ovr 1 -srcwin 1000 1000 512 512 "$URL" remote_ovr_win.tif
gdal_translate -q -ovr 1 -srcwin 1000 1000 512 512 www/istria.vtz local_ovr_win.tif
"$VTZ" -q decode www/istria.vtz --overview 2 --window 250,250,128,128 -o cli_ovr_win.tif
"$PY" req.py same remote_ovr_win.tif local_ovr_win.tif
"$PY" req.py same remote_ovr_win.tif cli_ovr_win.tif
"$PY" req.py window ovr_win.log open.log istria.json "$size" 1000 1000 512 512 0 "overview 2 window 1000,1000 512x512"
ok "a window of overview 2: the local samples and vtz decode --overview 2 --window, only its tiles"

step "4. the whole raster and its statistics: each tile fetched once"
logged whole gdal_translate -q "$URL" remote_whole.tif
"$VTZ" -q decode www/istria.vtz -o cli_whole.tif
"$PY" req.py same remote_whole.tif cli_whole.tif
"$PY" req.py each_once whole.log open.log "$size"
logged stats gdalinfo -stats "$URL" >/dev/null
"$PY" req.py each_once stats.log open.log "$size"
ok "gdal_translate of the whole raster equals vtz decode; gdalinfo -stats (block by block) fetched each tile once"

step "5. a server that stops serving the file after the open: a clear read error"
"$PY" req.py read_error "$URL" www/istria.vtz

echo "all remote (/vsicurl/) checks passed"
