#!/usr/bin/env bash
# Tiling benchmark (issue 12): vtz encode/decode wall time and peak memory over the SRTM1
# sizes 600², 1200², 2400², 3600² and the ~20000² mosaic, threads 1 vs 2, tiled vs untiled,
# 512² window decodes from the mosaic, round-trip checks with compare.py, and SZ3 / LERC
# through ../shared/tools/peers at the same absolute bound. Prints Markdown tables on stdout.
#
# Usage: benches/tiles/run.sh VTZ_BIN [RUNS]          (RUNS: runs per measurement, default 3)
# Inputs: made first by `make_inputs.py $INPUTS` (default INPUTS=/work/bigdata/tiles).
# Needs: bash 5, GNU time at /usr/bin/time, a Python with numpy==2.4.6, tifffile==2026.3.3,
# imagecodecs==2026.3.6 and, for the peers, the harness's requirements (pysz==1.1.0,
# pylerc==4.2.0, scipy, ...: ../shared/tools/peers/requirements.txt); /work/venv has them all.
# It builds nothing: it runs the VTZ_BIN it is given (CARGO_TARGET_DIR is not used).
#
# Environment (defaults in brackets):
#   INPUTS [/work/bigdata/tiles]     where make_inputs.py wrote srtm1_*.f32/.json/.tif, mosaic
#   PY [/work/venv/bin/python]       the Python above
#   SIZES ["600 1200 2400 3600"]     which SRTM1 rasters (3600 = srtm1_full)
#   MOSAIC [$INPUTS/mosaic20k.tif]   the mosaic; empty: no mosaic (windows then come from the
#                                    largest of SIZES)
#   MAX_ERROR [1%]                   the bound given to --max-error (N% or data units)
#   THREAD_FLAG [--threads]          the flag that sets the thread count, followed by T; empty:
#                                    no flag at all and one run per measurement (T shows as "-")
#   DEC_THREAD_FLAG [THREAD_FLAG]    the same for decode (empty: decode gets no thread flag)
#   THREADS ["1 2"]                  thread counts; the first is used for every size (and the
#                                    size-exponent fit), all of them for THREAD_SIZES
#   THREAD_SIZES ["2400 3600"]       sizes measured at every count in THREADS
#   MOSAIC_THREADS [last of THREADS] thread count(s) for the mosaic
#   TILE_FLAGS [""]                  extra encode flags of the default (tiled) variant, e.g.
#                                    "--tile 512"
#   UNTILED_FLAGS [--tile 0]         encode flags of the untiled variant; empty: no such variant
#   UNTILED_MAX [2400]               the untiled variant only for sizes up to this
#   ENC_FLAGS [-q --json], DEC_FLAGS [-q]   passed to every encode / decode
#   MOSAIC_RUNS [1]                  runs of the mosaic encode and decode
#   WINDOW_FLAG [--window]           empty: no window decodes
#   WINDOW_SIZE [512]  WINDOW_RUNS [5]
#   PEERS [/work/shared/tools/peers/peers.py]; empty: no SZ3/LERC
#   PEERS_RUNS [RUNS]                the harness's --repeat (it keeps the best)
#   PEERS_ONLY [0]                   1: only the peers part (no VTZ_BIN needed: pass "-")
#   REPORT [""]                      also write the Markdown here, and the raw rows beside it
#                                    (REPORT.rows.tsv, REPORT.results.jsonl)
#   KEEP_TMP [0]                     1: keep the temporary directory (its path is printed)
#   TMPDIR [/tmp]                    where the temporary directory goes (the mosaic's .vtz and
#                                    decoded .tif need ~1 GB)
set -euo pipefail
export LC_ALL=C

if [ $# -lt 1 ] || [ $# -gt 2 ]; then
  sed -n '2,9p' "$0" >&2
  exit 2
fi
vtz=$1
runs=${2:-3}
here=$(cd "$(dirname "$0")" && pwd)
INPUTS=${INPUTS:-/work/bigdata/tiles}
PY=${PY:-/work/venv/bin/python}
SIZES=${SIZES:-600 1200 2400 3600}
MOSAIC=${MOSAIC-$INPUTS/mosaic20k.tif}
MAX_ERROR=${MAX_ERROR:-1%}
THREAD_FLAG=${THREAD_FLAG---threads}
DEC_THREAD_FLAG=${DEC_THREAD_FLAG-$THREAD_FLAG}
THREADS=${THREADS:-1 2}
THREAD_SIZES=${THREAD_SIZES-2400 3600}
TILE_FLAGS=${TILE_FLAGS-}
UNTILED_FLAGS=${UNTILED_FLAGS---tile 0}
UNTILED_MAX=${UNTILED_MAX:-2400}
ENC_FLAGS=${ENC_FLAGS--q --json}
DEC_FLAGS=${DEC_FLAGS--q}
MOSAIC_RUNS=${MOSAIC_RUNS:-1}
WINDOW_FLAG=${WINDOW_FLAG---window}
WINDOW_SIZE=${WINDOW_SIZE:-512}
WINDOW_RUNS=${WINDOW_RUNS:-5}
PEERS=${PEERS-/work/shared/tools/peers/peers.py}
PEERS_RUNS=${PEERS_RUNS:-$runs}
PEERS_ONLY=${PEERS_ONLY:-0}
REPORT=${REPORT:-}
KEEP_TMP=${KEEP_TMP:-0}

die() { echo "run.sh: $*" >&2; exit 2; }
[[ $runs =~ ^[1-9][0-9]*$ ]] || die "RUNS must be a positive integer"
[ -x /usr/bin/time ] || die "/usr/bin/time (GNU time) is missing: apt-get install time"
[ -x "$PY" ] || die "PY=$PY is not executable"
[ -d "$INPUTS" ] || die "INPUTS=$INPUTS does not exist: run make_inputs.py $INPUTS first"
if [ "$PEERS_ONLY" != 1 ]; then
  [ -x "$vtz" ] || die "VTZ_BIN $vtz is not executable"
  vtz=$(cd "$(dirname "$vtz")" && pwd)/$(basename "$vtz")
fi
read -r -a thread_list <<< "$THREADS"
[ ${#thread_list[@]} -gt 0 ] || die "THREADS is empty"
if [ -z "$THREAD_FLAG" ]; then thread_list=(-); fi
MOSAIC_THREADS=${MOSAIC_THREADS:-${thread_list[-1]}}
read -r -a mosaic_threads <<< "$MOSAIC_THREADS"
if [ -z "$THREAD_FLAG" ]; then mosaic_threads=(-); fi
read -r -a tile_flags <<< "$TILE_FLAGS"
read -r -a untiled_flags <<< "$UNTILED_FLAGS"
read -r -a enc_flags <<< "$ENC_FLAGS"
read -r -a dec_flags <<< "$DEC_FLAGS"

name_of() { if [ "$1" = 3600 ]; then echo srtm1_full; else echo "srtm1_crop$1"; fi; }
for n in $SIZES; do
  for ext in f32 json tif; do
    [ -f "$INPUTS/$(name_of "$n").$ext" ] || die "$INPUTS/$(name_of "$n").$ext is missing (make_inputs.py)"
  done
done
if [ -n "$MOSAIC" ] && [ "$PEERS_ONLY" != 1 ]; then
  [ -f "$MOSAIC" ] || die "MOSAIC=$MOSAIC is missing (make_inputs.py, or MOSAIC= to skip it)"
fi

tmp=$(mktemp -d "${TMPDIR:-/tmp}/vtz_tiles.XXXXXX")
if [ "$KEEP_TMP" = 1 ]; then echo "temporary files kept in $tmp" >&2
else trap 'rm -rf "$tmp"' EXIT; fi
rows=$tmp/rows.tsv            # one line per timed command
results=$tmp/results.jsonl    # encode results (--json) and compare.py verdicts
printf 'kind\tinput\tsamples\tvariant\tthreads\trun\twall_s\tmaxrss_kb\tout_bytes\tstatus\n' > "$rows"
: > "$results"
failures=0
started=$(date -u +%Y-%m-%dT%H:%M:%SZ)

log() { echo "[$(date +%H:%M:%S)] $*" >&2; }

# measure KIND INPUT SAMPLES VARIANT THREADS RUN OUTFILE -- CMD...: time one command, append a
# row; on failure print its stderr, count it and return 1.
measure() {
  local kind=$1 input=$2 samples=$3 variant=$4 threads=$5 run=$6 out=$7
  shift 8
  rm -f "$out"
  local t0 t1 rc=0
  t0=$EPOCHREALTIME
  /usr/bin/time -v -o "$tmp/time.txt" "$@" > "$tmp/stdout.txt" 2> "$tmp/stderr.txt" || rc=$?
  t1=$EPOCHREALTIME
  local wall rss bytes=0 status=ok
  wall=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.4f", b - a }')
  rss=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$tmp/time.txt")
  [ -f "$out" ] && bytes=$(stat -c %s "$out")
  if [ "$rc" -ne 0 ]; then
    status="exit_$rc"
    failures=$((failures + 1))
    echo "FAILED (exit $rc): $*" >&2
    sed 's/^/    /' "$tmp/stderr.txt" | head -20 >&2
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$kind" "$input" "$samples" "$variant" \
    "$threads" "$run" "$wall" "${rss:-0}" "$bytes" "$status" >> "$rows"
  [ "$rc" -eq 0 ]
}

# thread_args FLAG T: the thread flag and T, or nothing.
thread_args() { if [ -n "$1" ] && [ "$2" != - ]; then printf '%s\n' "$1" "$2"; fi; }

# check SRC.tif DEC.tif BOUND LABEL [--at X,Y]: compare.py, verdict into results.jsonl.
check() {
  local src=$1 dec=$2 bound=$3 label=$4
  shift 4
  local rc=0
  "$PY" "$here/compare.py" "$src" "$dec" --bound "$bound" --json "$@" > "$tmp/cmp.json" || rc=$?
  if [ -s "$tmp/cmp.json" ]; then
    "$PY" -c 'import json,sys; d=json.load(open(sys.argv[1])); d["label"]=sys.argv[2]; d["type"]="compare"; print(json.dumps(d))' \
      "$tmp/cmp.json" "$label" >> "$results"
  fi
  if [ "$rc" -ne 0 ]; then
    failures=$((failures + 1))
    echo "CHECK FAILED ($label): compare.py $src $dec --bound $bound $*" >&2
    cat "$tmp/cmp.json" >&2 || true
  fi
}

# encode_decode INPUT SRC_TIF NAME SAMPLES VARIANT T NRUNS FLAGS...: NRUNS encodes, then NRUNS
# decodes of the last .vtz, then the round-trip checks. Leaves $tmp/NAME.VARIANT.T.vtz/.tif.
encode_decode() {
  local input=$1 srctif=$2 name=$3 samples=$4 variant=$5 t=$6 nruns=$7
  shift 7
  local tag=$name.$variant.$t
  local vtzf=$tmp/$tag.vtz dec=$tmp/$tag.tif targs dargs r ok=1
  mapfile -t targs < <(thread_args "$THREAD_FLAG" "$t")
  mapfile -t dargs < <(thread_args "$DEC_THREAD_FLAG" "$t")
  for ((r = 1; r <= nruns; r++)); do
    log "encode $name $variant T=$t run $r/$nruns"
    if ! measure encode "$name" "$samples" "$variant" "$t" "$r" "$vtzf" -- \
        "$vtz" encode "$input" -o "$vtzf" --max-error "$MAX_ERROR" "${enc_flags[@]}" "$@" "${targs[@]}"; then
      ok=0; break
    fi
  done
  [ "$ok" = 1 ] || return 1
  # The encoder's own report (--json) of the last run, when it printed one.
  "$PY" -c 'import json,sys
try: d = json.loads(open(sys.argv[1]).read())
except Exception: sys.exit(0)
d.update(type="encode", input=sys.argv[2], variant=sys.argv[3], threads=sys.argv[4]); print(json.dumps(d))' \
    "$tmp/stdout.txt" "$name" "$variant" "$t" >> "$results"
  for ((r = 1; r <= nruns; r++)); do
    log "decode $name $variant T=$t run $r/$nruns"
    measure decode "$name" "$samples" "$variant" "$t" "$r" "$dec" -- \
      "$vtz" decode "$vtzf" -o "$dec" "${dec_flags[@]}" "${dargs[@]}" || return 1
  done
  log "check $name $variant T=$t"
  check "$srctif" "$dec" "$MAX_ERROR" "$tag requested"
  # The achieved bound: the max error the encoder reported (if it reported one).
  local achieved
  achieved=$("$PY" -c 'import json,sys
for l in open(sys.argv[1]):
    d = json.loads(l)
    if d.get("type") == "encode" and [d["input"], d["variant"], d["threads"]] == sys.argv[2:5] and d.get("max_error") is not None:
        print(repr(float(d["max_error"])))' "$results" "$name" "$variant" "$t" | tail -1)
  [ -z "$achieved" ] || check "$srctif" "$dec" "$achieved" "$tag achieved"
}

in_list() { local x=$1; shift; for y in "$@"; do [ "$x" = "$y" ] && return 0; done; return 1; }

window_src=""; window_tif=""; window_name=""
if [ "$PEERS_ONLY" != 1 ]; then
  read -r -a thread_sizes <<< "$THREAD_SIZES"
  for n in $SIZES; do
    name=$(name_of "$n")
    samples=$((n * n))
    ts=("${thread_list[0]}")
    if in_list "$n" "${thread_sizes[@]}"; then ts=("${thread_list[@]}"); fi
    for t in "${ts[@]}"; do
      encode_decode "$INPUTS/$name.f32" "$INPUTS/$name.tif" "$name" "$samples" tiled "$t" "$runs" \
        "${tile_flags[@]}" || true
      if [ ${#untiled_flags[@]} -gt 0 ] && [ "$n" -le "$UNTILED_MAX" ]; then
        encode_decode "$INPUTS/$name.f32" "$INPUTS/$name.tif" "$name" "$samples" untiled "$t" \
          "$runs" "${untiled_flags[@]}" || true
      fi
    done
    if [ -f "$tmp/$name.tiled.${ts[0]}.vtz" ]; then
      window_src=$tmp/$name.tiled.${ts[0]}.vtz; window_tif=$INPUTS/$name.tif; window_name=$name
      window_w=$n
    fi
  done
  if [ -n "$MOSAIC" ]; then
    mw=$("$PY" -c 'import tifffile,sys; p=tifffile.TiffFile(sys.argv[1]).pages.first; print(p.imagewidth, p.imagelength)' "$MOSAIC")
    read -r mosaic_w mosaic_h <<< "$mw"
    mname=$(basename "$MOSAIC" .tif)
    fallback=("$window_src" "$window_tif" "$window_name" "${window_w:-0}")
    window_src=""
    for t in "${mosaic_threads[@]}"; do
      encode_decode "$MOSAIC" "$MOSAIC" "$mname" "$((mosaic_w * mosaic_h))" tiled "$t" \
        "$MOSAIC_RUNS" "${tile_flags[@]}" || true
      if [ -z "$window_src" ] && [ -f "$tmp/$mname.tiled.$t.vtz" ]; then
        window_src=$tmp/$mname.tiled.$t.vtz; window_tif=$MOSAIC; window_name=$mname
        window_w=$((mosaic_w < mosaic_h ? mosaic_w : mosaic_h))
      fi
    done
    if [ -z "$window_src" ]; then  # the mosaic failed: windows from the largest SRTM1 size
      window_src=${fallback[0]}; window_tif=${fallback[1]}; window_name=${fallback[2]}
      window_w=${fallback[3]}
    fi
    # The decoded mosaic (~1 GB with the .vtz) is not needed past this point.
    rm -f "$tmp/$mname".tiled.*.tif
  fi
  # 512² windows from one file, each a fresh process (cold file handle; the page cache is warm):
  # the corner, the centre (across the mosaic's quadrant seam), an unaligned spot, the far corner.
  if [ -n "$WINDOW_FLAG" ] && [ -n "$window_src" ] && [ "$window_w" -ge "$WINDOW_SIZE" ]; then
    ws=$WINDOW_SIZE
    positions=("0,0" "$(((window_w - ws) / 2)),$(((window_w - ws) / 2))"
               "$((window_w * 5 / 8 + 37)),$((window_w / 3 + 11))" "$((window_w - ws)),$((window_w - ws))")
    for pos in "${positions[@]}"; do
      x=${pos%,*}; y=${pos#*,}
      if [ $((x + ws)) -gt "$window_w" ]; then x=$((window_w - ws)); fi
      if [ $((y + ws)) -gt "$window_w" ]; then y=$((window_w - ws)); fi
      for ((r = 1; r <= WINDOW_RUNS; r++)); do
        log "window $x,$y of $window_name run $r/$WINDOW_RUNS"
        measure window "$window_name" $((ws * ws)) "$x,$y" - "$r" "$tmp/win.tif" -- \
          "$vtz" decode "$window_src" -o "$tmp/win.tif" "${dec_flags[@]}" "$WINDOW_FLAG" "$x,$y,$ws,$ws" || break
      done
      [ -f "$tmp/win.tif" ] && check "$window_tif" "$tmp/win.tif" "$MAX_ERROR" "window $window_name $x,$y" --at "$x,$y"
    done
  fi
fi

# Peers: SZ3 and LERC on the .f32 inputs at the same absolute bound (MAX_ERROR of each raster's
# range, from its sidecar stats, exactly as vtz computes it), best of PEERS_RUNS, one process.
if [ -n "$PEERS" ]; then
  [ -f "$PEERS" ] || die "PEERS=$PEERS is missing"
  for n in $SIZES; do
    name=$(name_of "$n")
    e=$("$PY" -c 'import json,sys
m = json.load(open(sys.argv[1])); b = sys.argv[2]
print(repr(float(b[:-1]) / 100 * (m["stats"]["max"] - m["stats"]["min"]) if b.endswith("%") else float(b)))' \
      "$INPUTS/$name.json" "$MAX_ERROR")
    log "peers sz3,lerc on $name at abs $e (best of $PEERS_RUNS)"
    if ! "$PY" "$PEERS" "$INPUTS/$name.f32" --codecs sz3,lerc --pct "" --abs "$e" \
        --repeat "$PEERS_RUNS" --csv "$tmp/peers_$name.csv" -q > "$tmp/peers_$name.md" 2> "$tmp/peers.err"; then
      failures=$((failures + 1)); echo "PEERS FAILED on $name:" >&2; cat "$tmp/peers.err" >&2
    fi
  done
fi

{
  echo "# vtz tiling benchmark"
  echo
  echo "- started $started, finished $(date -u +%Y-%m-%dT%H:%M:%SZ); machine: $(nproc) cores" \
       "($(lscpu | sed -n 's/^Model name: *//p' | head -1)), $(free -g | awk '/^Mem:/ {print $2}') GiB"
  if [ "$PEERS_ONLY" != 1 ]; then
    echo "- vtz: \`$vtz\` ($("$vtz" --version 2>/dev/null || echo "no --version")), $(stat -c %y "$vtz" | cut -d. -f1)"
  fi
  if [ "$PEERS_ONLY" = 1 ]; then
    echo "- command: \`PEERS_ONLY=1 MAX_ERROR=$MAX_ERROR SIZES='$SIZES' PEERS_RUNS=$PEERS_RUNS" \
         "$(basename "$0") $*\` (INPUTS=$INPUTS)"
  else
    echo "- command: \`$(basename "$0") $*\` with MAX_ERROR=$MAX_ERROR THREAD_FLAG='$THREAD_FLAG'" \
         "DEC_THREAD_FLAG='$DEC_THREAD_FLAG' THREADS='$THREADS' THREAD_SIZES='$THREAD_SIZES'" \
         "TILE_FLAGS='$TILE_FLAGS' UNTILED_FLAGS='$UNTILED_FLAGS' SIZES='$SIZES' MOSAIC='$MOSAIC'" \
         "RUNS=$runs MOSAIC_RUNS=$MOSAIC_RUNS PEERS_RUNS=$PEERS_RUNS (INPUTS=$INPUTS)"
  fi
  echo "- peers: $("$PY" -c 'import importlib.metadata as m; print(", ".join(f"{p} {m.version(p)}" for p in ("pysz", "pylerc", "numpy")))' 2>/dev/null || echo "versions unknown")"
  echo
  "$PY" "$here/summarize.py" "$rows" "$results" "$tmp" "${thread_list[0]}"
} > "$tmp/report.md"
cat "$tmp/report.md"
if [ -n "$REPORT" ]; then
  cp "$tmp/report.md" "$REPORT"
  cp "$rows" "$REPORT.rows.tsv"
  cp "$results" "$REPORT.results.jsonl"
fi
if [ "$failures" -gt 0 ]; then
  echo "run.sh: $failures failed command(s) or check(s), see above" >&2
  exit 1
fi
