#!/usr/bin/env bash
# Sites (Sibson) encode and decode time over growing rasters, one core: Istria crops 300²,
# 600², 1200² (centred in ../shared/corpus/srtm1_N45E013_istria_crop2400), that 2400² crop
# and the full 3600² SRTM1 tile (../shared/corpus/extra/srtm1_N45E013_full.png, metres =
# value − 32768), at 1 % of each raster's range (other bounds with BOUNDS=…, e.g. "1%,10"
# for a fixed 10 m too: the same detail per area at every size). Prints the bench's rows, the
# growth exponents (least squares of log time on log samples) and, per raster, the CLI's
# peak memory (/usr/bin/time -v) in bytes per sample for encode and decode.
# Usage: benches/sites_scaling.sh PYTHON_WITH_NUMPY [RUNS]
set -euo pipefail
py=$1; runs=${2:-1}; bounds=${BOUNDS:-1%}
here=$(cd "$(dirname "$0")/.." && pwd)
corpus=$here/../shared/corpus
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
cd "$here"
cargo build --release -q --bin vtz
bench=$(cargo bench --bench sites_speed --no-run 2>&1 | sed -n 's/.*(\(.*sites_speed-[0-9a-f]*\)).*/\1/p' | tail -1)
vtz=${CARGO_TARGET_DIR:-$here/target}/release/vtz
"$py" - "$corpus/srtm1_N45E013_istria_crop2400.f32" "$tmp" <<'PY'
import json, sys, numpy as np
src, out = sys.argv[1], sys.argv[2]
a = np.fromfile(src, "<f4").reshape(2400, 2400)
meta = json.load(open(src[:-4] + ".json"))
for n in (300, 600, 1200, 2400):
    o = (2400 - n) // 2
    a[o:o + n, o:o + n].astype("<f4").tofile(f"{out}/istria_{n}.f32")
    json.dump({"width": n, "height": n, "nodata": meta["nodata"], "source_dtype": "float32"},
              open(f"{out}/istria_{n}.json", "w"))
PY
files=("$tmp"/istria_300.f32 "$tmp"/istria_600.f32 "$tmp"/istria_1200.f32 "$tmp"/istria_2400.f32)
full=$corpus/extra/srtm1_N45E013_full.png
if [ -f "$full" ]; then
  "$vtz" convert "$full" "$tmp/srtm1_full_3600.tif" --png-offset -32768 --png-nodata 0 -q
  files+=("$tmp/srtm1_full_3600.tif")
else
  echo "SKIPPED the full tile: $full is absent" >&2
fi
taskset -c "${CORE:-0}" "$bench" --runs "$runs" --bounds "$bounds" "${files[@]}" | tee "$tmp/rows.tsv"
"$py" - "$tmp/rows.tsv" <<'PY'
import sys, numpy as np
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[1])][1:]
for b in sorted({r[2] for r in rows}):
    r = [x for x in rows if x[2] == b]
    n = np.log([float(x[1]) for x in r])
    for col, name in ((4, "encode"), (5, "decode")):
        t = np.log([float(x[col]) for x in r])
        print(f"growth exponent at {b}, {name}: {np.polyfit(n, t, 1)[0]:.3f} over {len(r)} sizes")
PY
"$py" - "$tmp/rows.tsv" "$vtz" "$tmp" "${files[@]}" <<'PY'
import os, re, subprocess, sys
rows_path, vtz, tmp, files = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
rows = [l.rstrip("\n").split("\t") for l in open(rows_path)][1:]
def peak(cmd):
    r = subprocess.run(["/usr/bin/time", "-v", "taskset", "-c", os.environ.get("CORE", "0")] + cmd,
                       capture_output=True, text=True, check=True)
    return int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr)[1]) * 1024
print("raster\tbound\tencode_peak_MB\tencode_B_per_sample\tdecode_peak_MB\tdecode_B_per_sample")
for f in files:
    stem = os.path.splitext(os.path.basename(f))[0]
    for r in rows:
        if r[0] != stem:
            continue
        n, b = int(r[1]), r[2]
        out = f"{tmp}/x.vtz"
        e = peak([vtz, "encode", f, "-o", out, "-f", "-q", "--method", "sibson", "--max-error", b])
        d = peak([vtz, "decode", out, "-o", f"{tmp}/x.tif", "-f", "-q"])
        print(f"{stem}\t{b}\t{e/1e6:.1f}\t{e/n:.1f}\t{d/1e6:.1f}\t{d/n:.1f}")
PY
