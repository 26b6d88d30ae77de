#!/usr/bin/env bash
# Remote reads (issue 36): the 20000² mosaic of benches/tiles at a 1 m bound as a `.vtz` and
# as two COGs written by GDAL (LERC MAX_Z_ERROR=1; DEFLATE PREDICTOR=2; both with internal
# overviews), served by a local nginx that logs each request's Range; for every read the
# requests, body bytes and wall time (median of RUNS fresh processes, the tools interleaved
# run by run so they share the machine's noise):
#
#   open      gdalinfo /vsicurl/URL (COGs; .vtz through the GDAL plugin), `vtz info URL`,
#             Python `vtz.open(URL)`
#   window    256² at six positions: gdal_translate -srcwin (COGs, plugin),
#             `vtz decode URL --window`, Python `vtz.open(URL).read(window=…)`; the samples
#             of run 1 are checked against the mosaic (max error ≤ the bound, same nodata)
#   overview  gdal_translate -outsize 1024 1024 (COGs, plugin), `vtz decode URL --overview 4`
#
# plus the files' sizes (a COG's overviews apart) and, per window, the tiles it touches at
# full resolution and their bytes (COG blocks; .vtz tiles whose coded samples it meets).
# A tool that cannot do a read yet (no URL support in the vtz binary, no plugin, no
# vtz.open in Python) gets "n/a: <why>" rows: the script runs the same before and after
# those land. Everything but the table goes to stderr.
#
#   benches/remote/run.sh DATA_DIR [RUNS]          (or VTZ_REMOTE_DATA=DATA_DIR; RUNS = 3)
#
# DATA_DIR (large: ~0.8 GB; keep it out of the repository, e.g. /work/bigdata/tiles) gets
# the inputs when they are missing, and keeps them between runs:
#   mosaic20k.tif           benches/tiles/make_inputs.py DATA_DIR --only mosaic (INPUTS_PYTHON,
#                           default /work/venv/bin/python: numpy, tifffile, imagecodecs)
#   mosaic.vtz              vtz encode mosaic20k.tif -o mosaic.vtz --max-error 1 (default
#                           tiling); encoded again whenever the vtz binary changes
#                           (mosaic.vtz.stamp holds its sha256), so a new container version
#                           is measured as written by the binary under test
#   mosaic_lerc.tif         gdal_translate -of COG -co COMPRESS=LERC -co MAX_Z_ERROR=1
#   mosaic_deflate.tif      gdal_translate -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2
# and the results: remote.md (stdout's tables), remote.csv (one row per read and tool),
# remote_runs.csv (one row per run, with each request's Range), remote_access.log (nginx's).
#
# Environment: VTZ_BIN (default: the newer of target/ci/vtz, target/release/vtz),
# VTZ_PLUGIN_DIR (target/gdal-plugin, from capi/build-gdal-plugin.sh), VTZ_PYTHON (python3:
# the Python whose `import vtz` is measured), GDAL_PYTHON (/usr/bin/python3: osgeo + numpy,
# for the checks and tables), PORT (a free one), NGINX (nginx; Debian: apt-get install -y
# nginx-light). Needs curl, bc, gdal_translate/gdalinfo (GDAL with curl).
#
# GDAL's /vsicurl/ options, set as a user reading COGs would (GDAL's COG and /vsicurl/
# pages, titiler's tuning notes) and the same for every GDAL read:
#   GDAL_DISABLE_READDIR_ON_OPEN=EMPTY_DIR   no directory listing and no probes for side
#                                            files (.aux.xml, .ovr, .msk) on opening
#   CPL_VSIL_CURL_ALLOWED_EXTENSIONS=.tif,.vtz  /vsicurl/ touches no other names
#   VSI_CACHE=TRUE                           a block cache on the handle (25 MB): a read
#                                            that comes back to the same bytes refetches nothing
#   GDAL_HTTP_MULTIRANGE=YES                 the ranges of one RasterIO fetched in parallel
#   GDAL_HTTP_MERGE_CONSECUTIVE_RANGES=YES   adjacent tiles in one request
#   CPL_VSIL_CURL_CHUNK_SIZE                 left at GDAL's default (16384): the granularity
#                                            a user gets; larger trades bytes for requests
set -uo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
usage() { echo "usage: $0 DATA_DIR [RUNS]   (or VTZ_REMOTE_DATA=DATA_DIR)" >&2; exit 2; }
say() { echo "remote: $*" >&2; }
die() { echo "remote: error: $*" >&2; exit 1; }

data="${1:-${VTZ_REMOTE_DATA:-}}"
[ -n "$data" ] || usage
runs="${2:-${RUNS:-3}}"
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || usage
mkdir -p "$data" || die "cannot create $data"
data="$(cd "$data" && pwd)"

vtz="${VTZ_BIN:-}"
if [ -z "$vtz" ]; then
  for c in "$root/target/ci/vtz" "$root/target/release/vtz"; do
    if [ -x "$c" ] && { [ -z "$vtz" ] || [ "$c" -nt "$vtz" ]; }; then vtz="$c"; fi
  done
fi
[ -n "$vtz" ] && [ -x "$vtz" ] || die "no vtz binary: set VTZ_BIN or build target/ci/vtz"
plugin_dir="${VTZ_PLUGIN_DIR:-$root/target/gdal-plugin}"
vtz_python="${VTZ_PYTHON:-python3}"
inputs_python="${INPUTS_PYTHON:-/work/venv/bin/python}"
gdal_python="${GDAL_PYTHON:-/usr/bin/python3}"
nginx="${NGINX:-$(command -v nginx || echo /usr/sbin/nginx)}"
max_error=1
overview_k=4 # 20000 / 2^4 = 1250: the level gdal_translate -outsize 1024 reads from a COG
for t in curl bc gdalinfo gdal_translate; do
  command -v "$t" >/dev/null || die "$t is not installed"
done
[ -x "$nginx" ] || die "nginx not found (Debian: apt-get install -y nginx-light)"
"$gdal_python" -c 'import osgeo, numpy' 2>/dev/null || die "$gdal_python lacks osgeo or numpy"
table_py() { "$gdal_python" "$here/remote_table.py" "$@"; }
now() { date +%s.%N; }

# --- inputs (built once, kept in DATA_DIR) -----------------------------------------------
src="$data/mosaic20k.tif"
if [ ! -f "$src" ]; then
  say "building $src (make_inputs.py --only mosaic)"
  "$inputs_python" "$root/benches/tiles/make_inputs.py" "$data" --only mosaic >&2 ||
    die "make_inputs.py failed"
fi

stamp="vtz $(sha256sum "$vtz" | cut -d' ' -f1) max_error=$max_error"
# KEEP_VTZ=1 keeps a mosaic.vtz encoded earlier (by an encoder that writes the same bytes:
# say which in the results), e.g. when only the readers changed since.
if [ "${KEEP_VTZ:-0}" = 1 ] && [ -f "$data/mosaic.vtz.stamp" ]; then
  say "KEEP_VTZ=1: keeping mosaic.vtz ($(cat "$data/mosaic.vtz.stamp"))"
elif [ ! -f "$data/mosaic.vtz" ] || [ "$(cat "$data/mosaic.vtz.stamp" 2>/dev/null)" != "$stamp" ]; then
  say "encoding mosaic.vtz with $vtz (--max-error $max_error, default tiling)"
  rm -f "$data/mosaic.vtz.stamp"
  s=$(now)
  "$vtz" encode "$src" -o "$data/mosaic.vtz" --max-error "$max_error" -f -q --json \
    >"$data/mosaic.vtz.encode.json" || die "vtz encode failed"
  e=$(now)
  echo "$e - $s" | bc >"$data/mosaic.vtz.encode_s"
  echo "$stamp" >"$data/mosaic.vtz.stamp"
fi
"$vtz" info "$data/mosaic.vtz" --json >"$data/mosaic.vtz.info.json" 2>/dev/null ||
  say "vtz info --json on the local file failed: no tile layout for the table"

make_cog() { # NAME CREATION-OPTIONS...
  local out="$data/$1"; shift
  [ -f "$out" ] && return 0
  say "writing $out (gdal_translate -of COG $*)"
  local s e
  s=$(now)
  gdal_translate -q -of COG "$@" "$src" "$out.tmp.tif" || die "gdal_translate -of COG $* failed"
  e=$(now)
  mv -f "$out.tmp.tif" "$out"
  echo "$e - $s" | bc >"$out.write_s"
}
make_cog mosaic_lerc.tif -co COMPRESS=LERC -co MAX_Z_ERROR="$max_error"
make_cog mosaic_deflate.tif -co COMPRESS=DEFLATE -co PREDICTOR=2

# Six 256² windows: the corner; inside one .vtz tile (Gabon); the quadrant seam, across four
# .vtz tiles' corner; across .vtz tile borders (4000, 15000) and COG block borders (4096,
# 14848) at once; Kauai's largest void (the mosaic has no all-nodata 256² area: 4029
# nodata samples here, the most of any 64-aligned window); the far corner (partial COG
# blocks).
positions=(corner:0,0 inside:14567,2345 seam:9872,9872 borders:3900,14800 void:5184,15616
  far:19744,19744)
layout_args=()
for p in "${positions[@]}"; do layout_args+=(--window "${p#*:},256,256"); done

work="$(mktemp -d "${TMPDIR:-/tmp}/vtz-remote.XXXXXX")"
table_py layout "$data" --vtz-info "$data/mosaic.vtz.info.json" "${layout_args[@]}" \
  -o "$work/layout.json" || die "layout failed"

# --- the server ----------------------------------------------------------------------------
port="${PORT:-$("$gdal_python" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')}"
ng="$work/nginx"
mkdir -p "$ng"
user_line=""
[ "$(id -u)" -eq 0 ] && user_line="user $(id -un) $(id -gn);" # workers read DATA_DIR as us
cat >"$ng/nginx.conf" <<EOF
$user_line
worker_processes 1;
pid $ng/nginx.pid;
error_log $ng/error.log warn;
events { worker_connections 256; }
http {
  log_format ranges '\$request_method \$uri \$http_range \$status \$body_bytes_sent \$request_time';
  access_log $ng/access.log ranges;
  client_body_temp_path $ng/body; proxy_temp_path $ng/proxy; fastcgi_temp_path $ng/fastcgi;
  uwsgi_temp_path $ng/uwsgi; scgi_temp_path $ng/scgi;
  types { image/tiff tif; }
  default_type application/octet-stream;
  sendfile on;
  keepalive_requests 100000;
  server {
    listen 127.0.0.1:$port;
    root $data;
    location / { }
  }
}
EOF
stop_server() {
  if [ -f "$ng/nginx.pid" ]; then
    local pid
    pid="$(cat "$ng/nginx.pid")"
    kill -QUIT "$pid" 2>/dev/null
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
  fi
  [ -f "$ng/access.log" ] && cp -f "$ng/access.log" "$data/remote_access.log"
  if [ -z "${KEEP_WORK:-}" ]; then rm -rf "$work"; else say "kept $work"; fi
}
trap stop_server EXIT
"$nginx" -p "$ng/" -c "$ng/nginx.conf" -e "$ng/error.log" || die "nginx did not start ($ng/error.log)"
base="http://127.0.0.1:$port"
for _ in $(seq 50); do curl -sf -o /dev/null "$base/mosaic.vtz" -r 0-0 && break; sleep 0.1; done
code="$(curl -s -o /dev/null -w '%{http_code}' -r 0-99 "$base/mosaic.vtz")"
[ "$code" = 206 ] || die "the server answers a Range request with $code, not 206"
say "serving $data at $base (nginx $("$nginx" -v 2>&1 | sed 's/.*nginx\///'))"

export GDAL_DISABLE_READDIR_ON_OPEN=EMPTY_DIR
export CPL_VSIL_CURL_ALLOWED_EXTENSIONS=".tif,.vtz"
export VSI_CACHE=TRUE
export GDAL_HTTP_MULTIRANGE=YES
export GDAL_HTTP_MERGE_CONSECUTIVE_RANGES=YES
unset CPL_VSIL_CURL_CHUNK_SIZE GDAL_DRIVER_PATH
export NO_PROXY="127.0.0.1,localhost" no_proxy="127.0.0.1,localhost"

# --- which tools can read a URL (probes are outside the marks: not counted) ----------------
na_plugin="" na_cli="" na_py=""
if [ ! -f "$plugin_dir/gdal_VTZ.so" ]; then
  na_plugin="n/a: no GDAL plugin at $plugin_dir/gdal_VTZ.so (capi/build-gdal-plugin.sh)"
elif ! GDAL_DRIVER_PATH="$plugin_dir" gdalinfo --format VTZ >/dev/null 2>&1; then
  na_plugin="n/a: GDAL does not load $plugin_dir/gdal_VTZ.so"
fi
if ! err="$("$vtz" info "$base/mosaic.vtz" 2>&1 >/dev/null)"; then
  na_cli="n/a: this vtz reads no URL ($(echo "$err" | grep -v '^$' | head -1 | tr '\t' ' '))"
fi
"$vtz_python" "$here/py_read.py" "$base/mosaic.vtz" open 2>"$work/py_probe"
case $? in
  0) ;;
  3) na_py="$(head -1 "$work/py_probe")" ;;
  *) na_py="n/a: vtz.open($base/mosaic.vtz) fails ($(head -1 "$work/py_probe"))" ;;
esac
for v in "$na_plugin" "$na_cli" "$na_py"; do [ -n "$v" ] && say "$v"; done

# --- the reads -----------------------------------------------------------------------------
runs_tsv="$work/runs.tsv"
printf 'key\tread\tposition\tformat\ttool\trun\trc\twall_s\tcheck\tnote\n' >"$runs_tsv"
key=0
mark() { curl -s -o /dev/null "$base/__mark__/$1/$2"; }
wait_mark() { # until the end mark is in the log (all of the run's lines are before it)
  for _ in $(seq 100); do
    grep -q " /__mark__/end/$1 " "$ng/access.log" && return 0
    sleep 0.05
  done
  say "warning: end mark $1 not seen in the log"
}
fmt_of() { case $1 in lerc) echo "COG LERC" ;; deflate) echo "COG DEFLATE" ;; *) echo ".vtz" ;; esac; }
vsi_of() { case $1 in lerc) echo "/vsicurl/$base/mosaic_lerc.tif" ;;
  deflate) echo "/vsicurl/$base/mosaic_deflate.tif" ;; *) echo "/vsicurl/$base/mosaic.vtz" ;; esac; }
tool_of() { # TOOL READ -> the program, as the table names it
  case "$1:$2" in
    lerc:open | deflate:open | plugin:open) echo "gdalinfo" ;;
    lerc:* | deflate:* | plugin:*) echo "gdal_translate" ;;
    cli:open) echo "vtz info" ;;
    cli:*) echo "vtz decode" ;;
    py:open) echo "vtz.open" ;;
    py:*) echo "vtz.open().read" ;;
  esac
}
na_of() { case $1 in plugin) echo "$na_plugin" ;; cli) echo "$na_cli" ;; py) echo "$na_py" ;; *) echo "" ;; esac; }
# do_read TOOL READ X Y: one read in a fresh process; output in $work/out.tif or out.npy
do_read() {
  local tool=$1 read=$2 x=$3 y=$4 gd=()
  [ "$tool" = plugin ] && gd=(env GDAL_DRIVER_PATH="$plugin_dir")
  case "$tool:$read" in
    lerc:open | deflate:open | plugin:open) "${gd[@]}" gdalinfo "$(vsi_of "$tool")" ;;
    lerc:window | deflate:window | plugin:window)
      "${gd[@]}" gdal_translate -q -srcwin "$x" "$y" 256 256 "$(vsi_of "$tool")" "$work/out.tif" ;;
    lerc:overview | deflate:overview | plugin:overview)
      "${gd[@]}" gdal_translate -q -outsize 1024 1024 "$(vsi_of "$tool")" "$work/out.tif" ;;
    cli:open) "$vtz" info "$base/mosaic.vtz" ;;
    cli:window) "$vtz" decode "$base/mosaic.vtz" --window "$x,$y,256,256" -o "$work/out.tif" -f -q ;;
    cli:overview) "$vtz" decode "$base/mosaic.vtz" --overview "$overview_k" -o "$work/out.tif" -f -q ;;
    py:open) "$vtz_python" "$here/py_read.py" "$base/mosaic.vtz" open ;;
    py:window) "$vtz_python" "$here/py_read.py" "$base/mosaic.vtz" window "$x,$y,256,256" "$work/out.npy" ;;
  esac
}
# measure READ LABEL X Y TOOL...: RUNS runs of each tool, interleaved; checks on run 1
measure() {
  local read=$1 label=$2 x=$3 y=$4 tool r na rc s e wall chk note out bound
  shift 4
  for r in $(seq "$runs"); do
    for tool in "$@"; do
      key=$((key + 1))
      na="$(na_of "$tool")"
      if [ -n "$na" ]; then # one row saying why, no run
        [ "$r" -eq 1 ] && printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t\t\t%s\n' "$key" "$read" "$label" \
          "$(fmt_of "$tool")" "$(tool_of "$tool" "$read")" 1 na "$na" >>"$runs_tsv"
        continue
      fi
      rm -f "$work/out.tif" "$work/out.npy"
      mark begin "$key"
      s=$(now)
      do_read "$tool" "$read" "$x" "$y" >"$work/stdout" 2>"$work/stderr"
      rc=$?
      e=$(now)
      sleep 0.05
      mark end "$key"
      wait_mark "$key"
      wall="$(printf "%.6f" "$(echo "$e - $s" | bc)")"
      chk="" note=""
      if [ "$rc" -ne 0 ]; then
        note="$(grep -v '^$' "$work/stderr" | head -1 | tr '\t' ' ')"
        say "$read $label $tool run $r: exit $rc: $note"
      elif [ "$r" -eq 1 ]; then
        out="$work/out.tif"
        [ "$tool" = py ] && out="$work/out.npy"
        if [ "$read" = window ]; then
          bound=$max_error
          [ "$tool" = deflate ] && bound=0
          chk="$(table_py check "$src" "$x,$y,256,256" "$out" --bound "$bound" 2>&1 | tail -1)"
        elif [ "$read" = overview ]; then
          chk="$(table_py size "$out" 2>&1 | tail -1)"
        fi
      fi
      printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$key" "$read" "$label" "$(fmt_of "$tool")" \
        "$(tool_of "$tool" "$read")" "$r" "$rc" "$wall" "$chk" "$note" >>"$runs_tsv"
    done
  done
}

say "open (RUNS=$runs)"
measure open - 0 0 lerc deflate plugin cli py
for p in "${positions[@]}"; do
  xy="${p#*:}"
  say "window $p"
  measure window "${p%%:*} $xy" "${xy%,*}" "${xy#*,}" lerc deflate plugin cli py
done
say "overview"
measure overview "1024² (vtz: --overview $overview_k)" 0 0 lerc deflate plugin cli

# --- the tables ----------------------------------------------------------------------------
sleep 0.2
{
  echo "Measured $(date -u '+%Y-%m-%d %H:%M UTC') on $(uname -n) ($(nproc) cores), commit" \
    "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo '?'), $("$vtz" --version 2>/dev/null | head -1)" \
    "($vtz), $(gdalinfo --version | cut -d, -f1), nginx $("$nginx" -v 2>&1 | sed 's/.*nginx\///'), RUNS=$runs;" \
    "encode $(cat "$data/mosaic.vtz.encode_s" 2>/dev/null || echo '?') s."
  echo
  table_py table "$ng/access.log" "$runs_tsv" "$work/layout.json" \
    --csv "$data/remote.csv" --runs-csv "$data/remote_runs.csv"
} | tee "$data/remote.md"
rc=${PIPESTATUS[0]}
say "tables in $data/remote.md, remote.csv, remote_runs.csv; log in $data/remote_access.log"
exit "$rc"
