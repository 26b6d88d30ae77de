#!/usr/bin/env bash
# The GDAL driver plugin's checks (CI): GDAL programs and osgeo Python read, window and
# write .vtz files through gdal_VTZ.so exactly as the vtz CLI decodes them.
#
#   capi/gdal/check.sh VTZ_CLI PLUGIN_DIR
#   e.g. capi/gdal/check.sh target/release/vtz target/gdal-plugin
#
# Needs gdal-bin and python3-gdal (with numpy). Exits non-zero on the first failure.
# MUTATIONS (default 1000) sets how many mutated files check 8 opens.
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

# The python with osgeo.gdal (Debian's python3-gdal is for /usr/bin/python3).
PY="${PYTHON:-}"
if [ -z "$PY" ]; then
    for p in python3 /usr/bin/python3; do
        if "$p" -c 'import osgeo.gdal, numpy' 2>/dev/null; then PY="$p"; break; fi
    done
fi
[ -n "$PY" ] || { echo "FAIL: no python3 with osgeo.gdal and numpy (apt-get install python3-gdal)" >&2; exit 1; }

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
export GDAL_PAM_ENABLED=NO   # no .aux.xml files beside the test files
step() { echo "== $*"; }
ok() { echo "   ok: $*"; }

# Python helpers, one subcommand each (the compare logic lives here).
cat >chk.py <<'PYEOF'
import json, os, random, subprocess, sys
from concurrent.futures import ThreadPoolExecutor
import numpy as np
from osgeo import gdal, osr
gdal.UseExceptions()

def fail(msg):
    print("FAIL: " + msg, file=sys.stderr)
    sys.exit(1)

def info(path):
    out = subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, text=True).stdout
    return json.loads(out)

def md(obj, domain=""):
    # TIFFTAG_* items are the TIFF container's (vtz decode writes resolution tags), not data.
    d = (obj.get("metadata") or {}).get(domain, {})
    return {k: v for k, v in d.items() if not (domain == "" and k.startswith("TIFFTAG_"))}

def make_float(src, dst):
    """A Float32 DEM with nodata (-9999) holes, band description, unit and metadata."""
    s = gdal.Open(src)
    a = s.ReadAsArray().astype(np.float32)[600:1200, 200:1000]  # the island and its coast
    a = a + np.float32(0.25) * np.sin(np.arange(800, dtype=np.float32) / 7)[None, :]
    a[a <= 0] = -9999.0
    a[50:80, 300:400] = -9999.0
    gt = list(s.GetGeoTransform()); gt[0] += 200 * gt[1]; gt[3] += 600 * gt[5]
    d = gdal.GetDriverByName("GTiff").Create(dst, 800, 600, 1, gdal.GDT_Float32)
    d.SetGeoTransform(gt); d.SetProjection(s.GetProjection())
    d.SetMetadataItem("SOURCE", "kauai & test <float>")
    b = d.GetRasterBand(1); b.WriteArray(a); b.SetNoDataValue(-9999.0)
    b.SetDescription("elevation"); b.SetUnitType("m"); b.SetMetadataItem("VERTICAL_DATUM", "EGM96")
    v = a[a != -9999.0]
    print(f"   float.tif: {a.shape[1]}x{a.shape[0]} Float32, {100 * (1 - v.size / a.size):.0f}% nodata, valid {v.min():.2f} .. {v.max():.2f}")

def make_plain(src, dst):
    """A UInt16 raster without georeferencing or nodata."""
    a = gdal.Open(src).ReadAsArray()[900:1100, 300:600].astype(np.int32) + 100
    d = gdal.GetDriverByName("GTiff").Create(dst, 300, 200, 1, gdal.GDT_UInt16)
    d.GetRasterBand(1).WriteArray(np.clip(a, 0, 65535).astype(np.uint16))

def same_info(vtz, tif):
    """gdalinfo of the .vtz shows what gdalinfo of its decoded GeoTIFF shows."""
    a, b = info(vtz), info(tif)
    if a["driverShortName"] != "VTZ":
        fail(f"{vtz}: opened by {a['driverShortName']}, not VTZ")
    checks = {
        "size": (a["size"], b["size"]),
        "geoTransform": (a.get("geoTransform"), b.get("geoTransform")),
        "metadata": (md(a), md(b)),
        "band type": (a["bands"][0]["type"], b["bands"][0]["type"]),
        "nodata": (a["bands"][0].get("noDataValue"), b["bands"][0].get("noDataValue")),
        "band metadata": (md(a["bands"][0]), md(b["bands"][0])),
        "band description": (a["bands"][0].get("description"), b["bands"][0].get("description")),
        "band unit": (a["bands"][0].get("unit"), b["bands"][0].get("unit")),
        "band count": (len(a["bands"]), len(b["bands"])),
    }
    for what, (x, y) in checks.items():
        if x != y:
            fail(f"{vtz}: {what} {x!r} != {tif}'s {y!r}")
    wa = a.get("coordinateSystem", {}).get("wkt", "")
    wb = b.get("coordinateSystem", {}).get("wkt", "")
    if bool(wa) != bool(wb):
        fail(f"{vtz}: CRS present {bool(wa)} vs {bool(wb)}")
    if wa:
        sa, sb = osr.SpatialReference(wkt=wa), osr.SpatialReference(wkt=wb)
        if not sa.IsSame(sb):
            fail(f"{vtz}: CRS differs:\n{wa}\n--- vs ---\n{wb}")
    st = md(a, "IMAGE_STRUCTURE")
    for k in ("COMPRESSION", "MAX_Z_ERROR", "VTZ_TILED"):
        if k not in st:
            fail(f"{vtz}: no {k} in the IMAGE_STRUCTURE metadata: {st}")
    print(f"   {os.path.basename(vtz)}: size {a['size']}, nodata {checks['nodata'][0]}, "
          f"CRS {('same text' if wa == wb else 'IsSame') if wa else 'none'}, metadata {md(a)} / band {md(a['bands'][0])}, "
          f"{st['VTZ_TILED']=} {st['MAX_Z_ERROR']=}")

def notiff(d):
    return {k: v for k, v in d.items() if not k.startswith("TIFFTAG_")}

def arrays_equal(a, b):
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind == "f":
        bits = np.dtype(f"u{a.dtype.itemsize}")
        same = a.view(bits) == b.view(bits)
        return bool(np.all(same | (np.isnan(a) & np.isnan(b))))
    return bool(np.array_equal(a, b))

def same_raster(x, y):
    """Two GDAL rasters hold the same samples bit for bit, nodata, geotransform and CRS."""
    a, b = gdal.Open(x), gdal.Open(y)
    ba, bb = a.GetRasterBand(1), b.GetRasterBand(1)
    if (a.RasterXSize, a.RasterYSize) != (b.RasterXSize, b.RasterYSize):
        fail(f"{x} / {y}: sizes differ")
    if not arrays_equal(ba.ReadAsArray(), bb.ReadAsArray()):
        fail(f"{x} / {y}: samples differ")
    if ba.GetNoDataValue() != bb.GetNoDataValue():
        fail(f"{x} / {y}: nodata {ba.GetNoDataValue()} != {bb.GetNoDataValue()}")
    if a.GetGeoTransform() != b.GetGeoTransform():
        fail(f"{x} / {y}: geotransform {a.GetGeoTransform()} != {b.GetGeoTransform()}")
    sa, sb = a.GetSpatialRef(), b.GetSpatialRef()
    if (sa is None) != (sb is None) or (sa is not None and not sa.IsSame(sb)):
        fail(f"{x} / {y}: CRS differs")

def same_crs(x, y):
    """Two rasters have the same CRS (not none) and geotransform."""
    a, b = gdal.Open(x), gdal.Open(y)
    sa, sb = a.GetSpatialRef(), b.GetSpatialRef()
    if sa is None or sb is None or not sa.IsSame(sb):
        fail(f"{x} / {y}: CRS differs: {sa and sa.ExportToProj4()} / {sb and sb.ExportToProj4()}")
    if a.GetGeoTransform() != b.GetGeoTransform():
        fail(f"{x} / {y}: geotransform {a.GetGeoTransform()} != {b.GetGeoTransform()}")

def same_samples(x, y):
    """Two rasters hold the same samples bit for bit."""
    a, b = gdal.Open(x).ReadAsArray(), gdal.Open(y).ReadAsArray()
    if a.shape != b.shape or not arrays_equal(a, b):
        fail(f"{x} / {y}: samples differ")

def overviews(vtz):
    """The band lists the format's overviews: level K is ceil(size / 2^K), down to ~64."""
    a = info(vtz)
    w, h = a["size"]
    got = [tuple(o["size"]) for o in a["bands"][0].get("overviews", [])]
    want = []
    k = 1
    while -(-max(w, h) // (1 << k)) >= 64:
        want.append((-(-w // (1 << k)), -(-h // (1 << k))))
        k += 1
    if got != want:
        fail(f"{vtz}: overviews {got}, expected {want}")

def overview_after_full(vtz, ov_tif, k):
    """Overview k read after the full resolution (an untiled file's comes from that cache)
    holds vtz decode --overview k's samples."""
    ds = gdal.Open(vtz)
    band = ds.GetRasterBand(1)
    band.ReadAsArray()
    got = band.GetOverview(int(k) - 1).ReadAsArray()
    if not arrays_equal(got, gdal.Open(ov_tif).ReadAsArray()):
        fail(f"{vtz}: overview {k} after a full read differs from vtz decode --overview {k}")

def windows(vtz, ref):
    """gdal_translate -srcwin, gdallocationinfo and osgeo ReadAsArray windows equal crops."""
    full = gdal.Open(ref).ReadAsArray()
    ds = gdal.Open(vtz)
    band = ds.GetRasterBand(1)
    bw, bh = band.GetBlockSize()
    W, H = ds.RasterXSize, ds.RasterYSize
    wins = [(0, 0, 17, 9), (bw - 5, bh - 7, 30, 20), (bw - 1, 0, 2, H), (0, bh - 1, W, 2),
            (max(0, W - 11), max(0, H - 13), min(W, 11), min(H, 13)), (bw // 2, bh // 2, min(W - bw // 2, 2 * bw + 3), min(H - bh // 2, bh + 1)),
            (1, 1, W - 2, H - 2), (W // 3, H // 3, 1, 1)]
    # Windows inside the raster (an untiled file's block is its width).
    wins = [(min(x, W - 1), min(y, H - 1), w, h) for (x, y, w, h) in wins]
    wins = [(x, y, max(1, min(w, W - x)), max(1, min(h, H - y))) for (x, y, w, h) in wins]
    for i, (x, y, w, h) in enumerate(wins):
        crop = full[y:y + h, x:x + w]
        out = f"win{i}.tif"
        subprocess.run(["gdal_translate", "-q", "-of", "GTiff", "-srcwin", str(x), str(y), str(w), str(h), vtz, out], check=True)
        got = gdal.Open(out).ReadAsArray().reshape(h, w)
        if not arrays_equal(got, crop):
            fail(f"{vtz}: gdal_translate -srcwin {x} {y} {w} {h} differs from the crop")
        arr = band.ReadAsArray(x, y, w, h)
        if not arrays_equal(arr, crop):
            fail(f"{vtz}: ReadAsArray({x}, {y}, {w}, {h}) differs from the crop")
        # Another buffer type, through GDAL's conversion.
        arr64 = band.ReadAsArray(x, y, w, h, buf_type=gdal.GDT_Float64)
        if not np.array_equal(arr64, crop.astype(np.float64), equal_nan=True):
            fail(f"{vtz}: ReadAsArray({x}, {y}, {w}, {h}, Float64) differs from the crop")
    # A resampled read goes through GDAL's default path: compare with GDAL's own result
    # on the reference (without the format's overviews, which the reference has not).
    refds = gdal.Open(ref)  # held: a band outlives no dataset in GDAL 3.6's Python
    gdal.SetConfigOption("VTZ_OVERVIEWS", "NO")
    plain = gdal.Open(vtz)
    gdal.SetConfigOption("VTZ_OVERVIEWS", None)
    if not arrays_equal(plain.GetRasterBand(1).ReadAsArray(0, 0, W, H, W // 3, H // 3),
                        refds.GetRasterBand(1).ReadAsArray(0, 0, W, H, W // 3, H // 3)):
        fail(f"{vtz}: a decimated read differs from the reference's")
    for (x, y) in [(0, 0), (min(W - 1, bw), min(H - 1, bh)), (W - 1, H - 1), (bw - 1, min(H - 1, bh))]:
        v = subprocess.run(["gdallocationinfo", "-valonly", vtz, str(x), str(y)], check=True,
                           capture_output=True, text=True).stdout.strip()
        # gdallocationinfo prints 15 significant digits: enough to tell Float32 apart.
        if full.dtype.type(float(v)) != full[y, x]:
            fail(f"{vtz}: gdallocationinfo {x} {y} = {v}, the decode has {full[y, x]}")
    print(f"   {os.path.basename(vtz)}: {len(wins)} windows (block {bw}x{bh}), 4 locations, a decimated read")

def bound(src, out_ref, e):
    """The decode of a GDAL-written .vtz is within e of the source on valid samples,
    with the same nodata mask (e = 0: bit for bit)."""
    s, d = gdal.Open(src), gdal.Open(out_ref)
    a = s.GetRasterBand(1).ReadAsArray().astype(np.float64)
    b = d.GetRasterBand(1).ReadAsArray().astype(np.float64)
    nd = s.GetRasterBand(1).GetNoDataValue()
    va = ~np.isnan(a) if nd is None else (a != nd) & ~np.isnan(a)
    vb = ~np.isnan(b) if nd is None else (b != nd) & ~np.isnan(b)
    if not np.array_equal(va, vb):
        fail(f"{out_ref}: nodata mask differs from {src}'s")
    err = float(np.max(np.abs(a[va] - b[va]))) if va.any() else 0.0
    if err > e:
        fail(f"{out_ref}: max |out - in| = {err} > {e}")
    if e == 0 and not arrays_equal(s.GetRasterBand(1).ReadAsArray(), d.GetRasterBand(1).ReadAsArray()):
        fail(f"{out_ref}: a lossless round trip changed bits")
    if d.GetGeoTransform() != s.GetGeoTransform():
        fail(f"{out_ref}: geotransform {d.GetGeoTransform()} != {s.GetGeoTransform()}")
    ss, ds_ = s.GetSpatialRef(), d.GetSpatialRef()
    if (ss is None) != (ds_ is None) or (ss is not None and not ds_.IsSame(ss)):
        fail(f"{out_ref}: CRS differs from {src}'s")
    if d.GetRasterBand(1).GetNoDataValue() != nd:
        fail(f"{out_ref}: nodata {d.GetRasterBand(1).GetNoDataValue()} != {nd}")
    for what, x, y in [("description", d.GetRasterBand(1).GetDescription(), s.GetRasterBand(1).GetDescription()),
                       ("unit", d.GetRasterBand(1).GetUnitType(), s.GetRasterBand(1).GetUnitType()),
                       ("band metadata", d.GetRasterBand(1).GetMetadata(), s.GetRasterBand(1).GetMetadata()),
                       ("metadata", notiff(d.GetMetadata()), notiff(s.GetMetadata()))]:
        if x != y:
            fail(f"{out_ref}: {what} {x!r} != {src}'s {y!r}")
    print(f"   {os.path.basename(out_ref)}: max |out - in| = {err} <= {e}, mask, georef, metadata kept")

def corrupt_offset(info_json):
    """The offset of a byte in the middle of a middle tile's block, and that tile's window."""
    d = json.load(open(info_json))
    idx = d["tiles"]["index"]
    t = idx[len(idx) // 2]
    print(t["offset"] + t["bytes"] // 2, t["tile"], t["x"], t["y"], t["width"], t["height"])

def fuzz(paths, n, seed=27):
    """gdalinfo -checksum on n mutated copies never dies of a signal (exit 0 or 1)."""
    rng = random.Random(seed)
    datas = [open(p, "rb").read() for p in paths]
    os.makedirs("fuzz", exist_ok=True)
    jobs = []
    for i in range(n):
        data = bytearray(datas[i % len(datas)])
        kind = rng.random()
        if kind < 0.15:
            data = data[:rng.randrange(len(data))]
        else:
            # 1-4 flips, half the time in the header and directory (first 256 bytes).
            for _ in range(rng.randint(1, 4)):
                hi = min(256, len(data)) if rng.random() < 0.5 else len(data)
                p = rng.randrange(hi)
                data[p] ^= rng.randrange(1, 256)
            if kind > 0.9:
                data = data[:rng.randrange(len(data))]
        p = f"fuzz/m{i}.vtz"
        open(p, "wb").write(bytes(data))
        jobs.append(p)
    def run(p):
        try:
            r = subprocess.run(["gdalinfo", "-checksum", p], capture_output=True, timeout=60)
        except subprocess.TimeoutExpired:
            return (p, "timeout")
        return (p, r.returncode)
    bad, counts = [], {}
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as ex:
        for p, rc in ex.map(run, jobs):
            counts[rc] = counts.get(rc, 0) + 1
            if rc not in (0, 1):
                bad.append((p, rc))
    if bad:
        for p, rc in bad[:10]:
            import shutil; shutil.copy(p, os.environ.get("FUZZ_KEEP", "/tmp"))
        fail(f"{len(bad)} of {n} mutated files ended gdalinfo with {bad[:10]} (copies kept in /tmp)")
    print(f"   {n} mutated files: exit codes {counts}")

def mapped(vtz, dec_tif, ref, e):
    """A file of u16 codes mapped by -32768 reads through the plugin as Int16 values (no
    offset or scale), every read the same as `vtz decode`'s GeoTIFF, within e of ref."""
    a = info(vtz)["bands"][0]
    if a["type"] != "Int16" or a.get("offset") not in (None, 0.0) or a.get("scale") not in (None, 1.0):
        fail(f"{vtz}: band type {a['type']}, offset {a.get('offset')}, scale {a.get('scale')}; expected Int16 values")
    if info(dec_tif)["bands"][0]["type"] != "Int16":
        fail(f"{dec_tif}: vtz decode wrote {info(dec_tif)['bands'][0]['type']}, expected Int16")
    ds = gdal.Open(vtz)
    got = ds.GetRasterBand(1).ReadAsArray()
    if not arrays_equal(got, gdal.Open(dec_tif).ReadAsArray()):
        fail(f"{vtz}: the band differs from vtz decode's GeoTIFF")
    r = gdal.Open(ref).ReadAsArray().astype(np.float64)
    err = float(np.max(np.abs(got.astype(np.float64) - r)))
    if err > e or got.min() >= 0:
        fail(f"{vtz}: max |band - source| = {err} > {e} (min {got.min()})")
    print(f"   {os.path.basename(vtz)}: Int16, values {got.min()} .. {got.max()}, max |err| {err} <= {e}")

def mapped_codes(vtz, dec_tif, png, offset, scale, e):
    """A file of u16 codes with offset and scale reads as UInt16 codes with GDAL's offset and
    scale, as `vtz decode`'s GeoTIFF; offset + scale * code is within e of the PNG's values."""
    for p in (vtz, dec_tif):
        pds = gdal.Open(p)  # held: a band outlives no dataset in GDAL 3.6's Python
        b = pds.GetRasterBand(1)
        if (gdal.GetDataTypeName(b.DataType), b.GetOffset(), b.GetScale()) != ("UInt16", offset, scale):
            fail(f"{p}: {gdal.GetDataTypeName(b.DataType)} offset {b.GetOffset()} scale {b.GetScale()}, expected UInt16 {offset} {scale}")
    ds = gdal.Open(vtz)
    got = ds.GetRasterBand(1).ReadAsArray()
    if not arrays_equal(got, gdal.Open(dec_tif).ReadAsArray()):
        fail(f"{vtz}: the codes differ from vtz decode's GeoTIFF")
    v = offset + scale * got.astype(np.float64)
    r = offset + scale * gdal.Open(png).ReadAsArray().astype(np.float64)
    err = float(np.max(np.abs(v - r)))
    if err > e + 1e-9:
        fail(f"{vtz}: max |value - source| = {err} > {e}")
    ov = ds.GetRasterBand(1).GetOverview(1).ReadAsArray()
    if not arrays_equal(ov, got[::4, ::4]) and ds.GetMetadataItem("VTZ_TILED", "IMAGE_STRUCTURE") == "NO":
        fail(f"{vtz}: overview 2 is not every 4th code")
    print(f"   {os.path.basename(vtz)}: UInt16 codes, offset {offset} scale {scale}, max |value err| {err:.3f} <= {e}")

def make_scaled(src, dst):
    """An Int16 GeoTIFF of codes with GDAL scale 10, unit metre (physical = 10 * code)."""
    s = gdal.Open(src)
    a = s.ReadAsArray()[600:1200, 200:1000]
    d = gdal.GetDriverByName("GTiff").Create(dst, a.shape[1], a.shape[0], 1, gdal.GDT_Int16)
    b = d.GetRasterBand(1)
    b.WriteArray(a); b.SetScale(10.0); b.SetOffset(0.0); b.SetUnitType("metre")
    nd = s.GetRasterBand(1).GetNoDataValue()
    if nd is not None:
        b.SetNoDataValue(nd)

def scaled_bound(src, out, e):
    """GDAL's values (offset + scale * sample) of out are within e of src's, with the same
    scale, offset and unit."""
    sds, dds = gdal.Open(src), gdal.Open(out)  # held: a band outlives no dataset
    s, d = sds.GetRasterBand(1), dds.GetRasterBand(1)
    for what, x, y in [("scale", d.GetScale(), s.GetScale()), ("offset", d.GetOffset() or 0.0, s.GetOffset() or 0.0),
                       ("unit", d.GetUnitType(), s.GetUnitType()), ("nodata", d.GetNoDataValue(), s.GetNoDataValue())]:
        if x != y:
            fail(f"{out}: {what} {x!r} != {src}'s {y!r}")
    a, b = s.ReadAsArray(), d.ReadAsArray()
    nd = s.GetNoDataValue()
    va = a != nd if nd is not None else np.ones(a.shape, bool)
    if not np.array_equal(va, b != nd if nd is not None else va):
        fail(f"{out}: nodata mask differs")
    pa = (s.GetOffset() or 0.0) + (s.GetScale() or 1.0) * a[va].astype(np.float64)
    pb = (d.GetOffset() or 0.0) + (d.GetScale() or 1.0) * b[va].astype(np.float64)
    err = float(np.max(np.abs(pa - pb)))
    if err > e:
        fail(f"{out}: max |value - source value| = {err} > {e} (scale {s.GetScale()})")
    print(f"   {os.path.basename(out)}: {gdal.GetDataTypeName(d.DataType)}, scale {d.GetScale()}, unit {d.GetUnitType()}: max |value err| {err} <= {e}")

def make_int64(dst, kind, big):
    """An Int64/UInt64 GeoTIFF: values near 2^60 (big) or below 2^53."""
    t = gdal.GDT_UInt64 if kind == "u" else gdal.GDT_Int64
    base = (1 << 60) if big == "1" else (1 << 40)
    a = (np.arange(64 * 48, dtype=np.int64).reshape(48, 64) * 3 + 1)
    a = (a + base).astype(np.uint64 if kind == "u" else np.int64)
    if kind == "i":
        a = -a
    d = gdal.GetDriverByName("GTiff").Create(dst, 64, 48, 1, t)
    d.GetRasterBand(1).WriteArray(a)

def same_values(src, out):
    """The same numbers (any types)."""
    a = gdal.Open(src).ReadAsArray()
    b = gdal.Open(out).ReadAsArray()
    if a.shape != b.shape or not all(int(x) == int(y) for x, y in zip(a.ravel().tolist(), b.ravel().tolist())):
        fail(f"{out}: values differ from {src}'s")
    ods = gdal.Open(out)
    print(f"   {os.path.basename(out)}: {gdal.GetDataTypeName(ods.GetRasterBand(1).DataType)}, the same {a.size} integers")

def make_masked(src, dst, t):
    """A GeoTIFF with an internal per-dataset mask (GDAL_TIFF_INTERNAL_MASK) and no nodata."""
    a = gdal.Open(src).ReadAsArray()[600:900, 200:600].astype(np.float32 if t == "f" else np.int16)
    gdal.SetConfigOption("GDAL_TIFF_INTERNAL_MASK", "YES")
    d = gdal.GetDriverByName("GTiff").Create(dst, a.shape[1], a.shape[0], 1,
                                             gdal.GDT_Float32 if t == "f" else gdal.GDT_Int16)
    b = d.GetRasterBand(1)
    b.WriteArray(a)
    b.CreateMaskBand(gdal.GMF_PER_DATASET)
    m = np.full(a.shape, 255, np.uint8)
    m[40:120, 50:170] = 0
    m[:, :7] = 0
    b.GetMaskBand().WriteArray(m)
    d = None
    gdal.SetConfigOption("GDAL_TIFF_INTERNAL_MASK", None)
    sds = gdal.Open(dst)  # held: a band outlives no dataset
    s = sds.GetRasterBand(1)
    if s.GetMaskFlags() != gdal.GMF_PER_DATASET or s.GetNoDataValue() is not None:
        fail(f"{dst}: mask flags {s.GetMaskFlags()}, nodata {s.GetNoDataValue()}")

def masked(src, vtz):
    """The .vtz's mask (from its nodata) is the source's mask band; valid samples exact."""
    sds, dds = gdal.Open(src), gdal.Open(vtz)  # held: a band outlives no dataset
    s, d = sds.GetRasterBand(1), dds.GetRasterBand(1)
    ms, md_ = s.GetMaskBand().ReadAsArray(), d.GetMaskBand().ReadAsArray()
    if not np.array_equal(ms != 0, md_ != 0):
        fail(f"{vtz}: {int(np.sum((ms != 0) != (md_ != 0)))} samples differ from the source's mask "
             f"(masked: {int(np.sum(ms == 0))} in the source, {int(np.sum(md_ == 0))} here; nodata {d.GetNoDataValue()})")
    a, b = s.ReadAsArray(), d.ReadAsArray()
    if not np.array_equal(a[ms != 0], b[ms != 0]):
        fail(f"{vtz}: valid samples changed")
    print(f"   {os.path.basename(vtz)}: {int(np.sum(ms == 0))} masked samples are nodata ({d.GetNoDataValue()}), the rest exact")

if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "make_float": make_float(*args)
    elif cmd == "make_plain": make_plain(*args)
    elif cmd == "same_info": same_info(*args)
    elif cmd == "same_raster": same_raster(*args)
    elif cmd == "same_samples": same_samples(*args)
    elif cmd == "same_crs": same_crs(*args)
    elif cmd == "windows": windows(*args)
    elif cmd == "overviews": overviews(*args)
    elif cmd == "overview_after_full": overview_after_full(*args)
    elif cmd == "bound": bound(args[0], args[1], float(args[2]))
    elif cmd == "corrupt_offset": corrupt_offset(*args)
    elif cmd == "fuzz": fuzz(args[1:], int(args[0]))
    elif cmd == "mapped": mapped(args[0], args[1], args[2], float(args[3]))
    elif cmd == "mapped_codes": mapped_codes(args[0], args[1], args[2], float(args[3]), float(args[4]), float(args[5]))
    elif cmd == "make_scaled": make_scaled(*args)
    elif cmd == "scaled_bound": scaled_bound(args[0], args[1], float(args[2]))
    elif cmd == "make_int64": make_int64(*args)
    elif cmd == "same_values": same_values(*args)
    elif cmd == "make_masked": make_masked(*args)
    elif cmd == "masked": masked(*args)
    else: fail(f"unknown helper {cmd}")
PYEOF

# Expect a command to fail with a GDAL error whose text matches a pattern (never a signal).
expect_error() {
    local pattern="$1"; shift
    local rc=0
    "$@" >out.txt 2>err.txt || rc=$?
    if [ "$rc" -eq 0 ] && [ -z "${ERROR_EXIT_0_OK:-}" ]; then echo "FAIL: '$*' succeeded, expected an error" >&2; exit 1; fi
    if [ "$rc" -gt 128 ]; then echo "FAIL: '$*' died of signal $((rc - 128))" >&2; cat err.txt >&2; exit 1; fi
    if ! grep -qiE "$pattern" err.txt; then
        echo "FAIL: '$*' gave no error matching /$pattern/:" >&2; cat err.txt >&2; exit 1
    fi
    ok "'$*' → exit $rc: $(grep -iE "$pattern" err.txt | head -1)"
}

step "1. gdalinfo --formats lists the VTZ driver (GDAL $(gdal-config --version 2>/dev/null || gdalinfo --version))"
gdalinfo --formats | grep -E '^ *VTZ -raster- \(rw' || { echo "FAIL: no VTZ driver in gdalinfo --formats" >&2; exit 1; }
ok "driver listed"

step "inputs: Kauai (Int16) as GeoTIFF, a Float32 DEM with nodata, each encoded untiled and tiled (--tile 256); a UInt16 raster without georeferencing or nodata"
"$VTZ" -q convert "$root/corpus/srtm3_N22W160_kauai.hgt" kauai.tif
"$PY" chk.py make_float kauai.tif float.tif
for s in kauai float; do
    "$VTZ" -q encode $s.tif -o ${s}_v1.vtz --max-error 1
    "$VTZ" -q encode $s.tif -o ${s}_v2.vtz --max-error 1 --tile 256
    "$VTZ" -q encode $s.tif -o ${s}_ll.vtz --lossless --tile 256
done
"$PY" chk.py make_plain kauai.tif plain.tif
"$VTZ" -q encode plain.tif -o plain_v1.vtz --max-error 2
"$VTZ" -q encode plain.tif -o plain_v2.vtz --lossless --tile 128
names="kauai_v1 kauai_v2 kauai_ll float_v1 float_v2 float_ll plain_v1 plain_v2"
for n in $names; do "$VTZ" -q decode $n.vtz -o $n.ref.tif; done
ok "$(ls *.vtz | tr '\n' ' ')"

step "2. gdalinfo of each .vtz shows the size, CRS, geotransform, nodata and metadata of its vtz-decoded GeoTIFF"
for n in $names; do "$PY" chk.py same_info $n.vtz $n.ref.tif; done
echo "   a CRS the source holds only as GeoTIFF keys (a Lambert azimuthal equal-area without an EPSG code):"
gdal_translate -q -a_srs "+proj=laea +lat_0=52 +lon_0=10 +x_0=4321000 +y_0=3210000 +ellps=GRS80 +units=m +no_defs" \
    -a_ullr 4000000 3500000 4120100 3379900 kauai.tif laea.tif
"$VTZ" -q encode laea.tif -o laea.vtz --max-error 1
"$PY" chk.py same_crs laea.tif laea.vtz
ok "laea.vtz: the same CRS and geotransform as laea.tif"

step "3. gdal_translate -of GTiff X.vtz equals vtz decode X.vtz bit for bit (and the golden files their expected samples)"
for n in $names; do
    gdal_translate -q -of GTiff $n.vtz $n.gdal.tif
    "$PY" chk.py same_raster $n.gdal.tif $n.ref.tif
    ok "$n"
done
for n in kauai_v2 float_v2; do
    # A 1 MB block cache: no prefetch or read-ahead, each swath decoded straight.
    GDAL_CACHEMAX=1 gdal_translate -q -of GTiff $n.vtz $n.gdal_c1.tif
    "$PY" chk.py same_raster $n.gdal_c1.tif $n.ref.tif
    ok "$n with GDAL_CACHEMAX=1"
done
for g in "$root"/tests/golden/v[12]_*.vtz; do
    b="$(basename "$g" .vtz)"
    [ -f "$root/tests/golden/$b.expected.f32" ] || continue
    gdal_translate -q -of ENVI -ot Float32 "$g" g.raw
    cmp -s g.raw "$root/tests/golden/$b.expected.f32" || { echo "FAIL: $b: GDAL's Float32 read differs from $b.expected.f32" >&2; exit 1; }
    ok "golden $b"
done

step "4 + 6. windows: gdal_translate -srcwin, gdallocationinfo and osgeo ReadAsArray(x, y, w, h) equal crops of the full decode"
for n in $names; do "$PY" chk.py windows $n.vtz $n.ref.tif; done
echo "   with a 1 MB block cache (windows over several tiles decode straight into the buffer):"
for n in kauai_v2 float_v2; do GDAL_CACHEMAX=1 "$PY" chk.py windows $n.vtz $n.ref.tif; done
echo "   overviews (gdaladdo's external .ovr): a reduced read is served from them, as QGIS draws"
for n in kauai_v1 kauai_v2; do
    cp $n.vtz ${n}_ovr.vtz
    gdaladdo -q -r average ${n}_ovr.vtz 2 4
    # 1201 / 4 = overview 2's size; --debug on shows every vtz_read the driver makes.
    gdal_translate --debug on -q -outsize 301 301 ${n}_ovr.vtz ${n}_small.tif 2>debug.log
    if grep -q "vtz_read of" debug.log; then
        echo "FAIL: $n: a reduced read with overviews decoded the .vtz: $(grep -m1 'vtz_read of' debug.log)" >&2
        exit 1
    fi
    gdal_translate -q -ovr 1 ${n}_ovr.vtz ${n}_ovr1.tif
    "$PY" chk.py same_samples ${n}_small.tif ${n}_ovr1.tif
    ok "$n: a 301 x 301 read is overview 2, and nothing of the .vtz was decoded for it"
done

echo "   overviews from the format itself (no .ovr): overview K is vtz decode --overview K, and a"
echo "   reduced read decodes the overview level, never the full resolution"
for n in $names; do
    "$PY" chk.py overviews $n.vtz
    for k in 1 2; do
        "$VTZ" -q decode $n.vtz -o $n.ov$k.tif --overview $k
        gdal_translate -q -ovr $((k - 1)) $n.vtz $n.gov$k.tif
        "$PY" chk.py same_samples $n.gov$k.tif $n.ov$k.tif
    done
    "$PY" chk.py overview_after_full $n.vtz $n.ov2.tif 2
    ok "$n: overviews 1 and 2 through GDAL equal vtz decode --overview 1 and 2 bit for bit"
done
for n in kauai_v1 kauai_v2; do
    gdal_translate --debug on -q -outsize 301 301 $n.vtz ${n}_small_own.tif 2>debug.log
    if grep "vtz_read of" debug.log | grep -v "level 2," >/dev/null; then
        echo "FAIL: $n: a 301 x 301 read decoded another level than overview 2: $(grep 'vtz_read of' debug.log | grep -v 'level 2,' | head -1)" >&2
        exit 1
    fi
    grep -q "vtz_read of level 2," debug.log || { echo "FAIL: $n: a 301 x 301 read did not read overview 2" >&2; exit 1; }
    "$PY" chk.py same_samples ${n}_small_own.tif $n.gov2.tif
    ok "$n: a 301 x 301 read is overview 2, decoded at that level only"
done
VTZ_OVERVIEWS=NO gdalinfo kauai_v1.vtz >noov.txt
! grep -q "Overviews" noov.txt || { echo "FAIL: VTZ_OVERVIEWS=NO still shows overviews" >&2; exit 1; }
ok "VTZ_OVERVIEWS=NO turns them off"

step "5. gdal_translate -of VTZ: the bound holds, vtz verify passes, LOSSLESS=YES round-trips exactly"
for s in kauai float plain; do
    gdal_translate -q -of VTZ -co MAX_Z_ERROR=1 $s.tif $s.gdal1.vtz
    "$VTZ" verify $s.gdal1.vtz
    "$VTZ" -q decode $s.gdal1.vtz -o $s.gdal1.tif
    "$PY" chk.py bound $s.tif $s.gdal1.tif 1
    gdal_translate -q -of VTZ -co LOSSLESS=YES -co TILE=256 -co EFFORT=3 -co THREADS=2 $s.tif $s.gdal0.vtz
    "$VTZ" verify $s.gdal0.vtz
    "$VTZ" -q decode $s.gdal0.vtz -o $s.gdal0.tif
    "$PY" chk.py bound $s.tif $s.gdal0.tif 0
    gdalinfo $s.gdal0.vtz >tiled_info.txt
    grep -q "VTZ_TILED=YES" tiled_info.txt || { echo "FAIL: TILE=256 did not tile" >&2; exit 1; }
done
gdal_translate -q -of VTZ -co MAX_Z_ERROR=1% -co METHOD=residual -co TILE=NONE kauai.tif kauai.pct.vtz
"$VTZ" verify kauai.pct.vtz
"$VTZ" -q decode kauai.pct.vtz -o kauai.pct.tif
"$PY" chk.py bound kauai.tif kauai.pct.tif 16.13   # 1% of Kauai's range (-34 .. 1579)
expect_error "contradict" gdal_translate -q -of VTZ -co LOSSLESS=YES -co MAX_Z_ERROR=1 kauai.tif bad.vtz
expect_error "EFFORT" gdal_translate -q -of VTZ -co EFFORT=12 kauai.tif bad.vtz
expect_error "one band" gdal_translate -q -of VTZ -b 1 -b 1 kauai.tif bad.vtz
expect_error "read-only|update" "$PY" -c "from osgeo import gdal; gdal.UseExceptions(); gdal.Open('kauai_v1.vtz', gdal.GA_Update)"

step "7. errors, not crashes: a corrupt tile, a truncated file, a point set"
"$VTZ" info --json kauai_v2.vtz >kauai_v2.json
read -r off tile tx ty tw th < <("$PY" chk.py corrupt_offset kauai_v2.json)
cp kauai_v2.vtz corrupt.vtz
"$PY" -c "import sys; f=open('corrupt.vtz','r+b'); f.seek($off); b=f.read(1); f.seek($off); f.write(bytes([b[0]^0x5a]))"
echo "   flipped byte $off (inside tile $tile at $tx,$ty ${tw}x${th})"
gdalinfo corrupt.vtz >/dev/null
ok "gdalinfo opens it (the tile is not read)"
expect_error "tile [0-9]+.*(corrupt|checksum)|(corrupt|checksum).*tile [0-9]+" gdal_translate -q -of GTiff corrupt.vtz corrupt.tif
# (GDAL 3.6's gdallocationinfo prints a read error but exits 0.)
ERROR_EXIT_0_OK=1 expect_error "tile [0-9]+.*(corrupt|checksum)|(corrupt|checksum).*tile [0-9]+" gdallocationinfo -valonly corrupt.vtz $((tx + 1)) $((ty + 1))
gdal_translate -q -of GTiff -srcwin 0 0 10 10 corrupt.vtz corner.tif
ok "a window away from tile $tile still reads"
head -c $(( $(stat -c %s kauai_v1.vtz) / 2 )) kauai_v1.vtz >trunc.vtz
expect_error "vtz: .*(truncat|short|end of|eof)" gdalinfo trunc.vtz
expect_error "point set .* not a raster" gdalinfo "$root/tests/golden/v3_points.vtz"

step "8. gdalinfo -checksum on ${MUTATIONS:-1000} mutated small files never crashes"
"$VTZ" -q convert "$root/corpus/srtm3_N22W160_kauai.hgt" big.tif
gdal_translate -q -srcwin 500 500 300 200 big.tif small.tif
"$VTZ" -q encode small.tif -o small_v2.vtz --max-error 1 --tile 64
"$VTZ" -q encode small.tif -o small_v1.vtz --max-error 2
"$VTZ" -q encode small.tif -o small_fast.vtz --effort 1
"$PY" chk.py fuzz "${MUTATIONS:-1000}" small_v2.vtz small_v1.vtz small_fast.vtz

step "9. integer codes with a value mapping, GDAL's scale/offset, 64-bit integers, mask bands"
echo "   a u16 PNG of SRTM heights + 32768 (Istria, -29 .. 1023 m) read with --png-offset -32768:"
echo "   GDAL's band is Int16 values (untiled, tiled), windows and overviews as vtz decodes them"
istria="$root/corpus/srtm1_N45E013_istria_crop2400.png"
"$VTZ" -q convert "$istria" istria.tif --png-offset -32768
for t in 0 512; do
    "$VTZ" -q encode "$istria" --png-offset -32768 -o "istria_$t.vtz" --max-error 1 --tile $t
    "$VTZ" -q decode "istria_$t.vtz" -o "istria_$t.tif"
    "$PY" chk.py mapped "istria_$t.vtz" "istria_$t.tif" istria.tif 1
    "$PY" chk.py windows "istria_$t.vtz" "istria_$t.tif"
    "$VTZ" -q decode "istria_$t.vtz" --overview 2 -o "istria_${t}_ov2.tif"
    "$PY" chk.py overview_after_full "istria_$t.vtz" "istria_${t}_ov2.tif" 2
    gdal_translate -q -of GTiff "istria_$t.vtz" "istria_${t}_gdal.tif"
    "$PY" chk.py same_samples "istria_${t}_gdal.tif" "istria_$t.tif"
done
echo "   the same PNG as decimetres (offset -3276.8, scale 0.1): UInt16 codes, GDAL offset/scale"
for t in 0 512; do
    "$VTZ" -q encode "$istria" --png-offset -3276.8 --png-scale 0.1 -o "dm_$t.vtz" --max-error 0.5 --tile $t
    "$VTZ" -q decode "dm_$t.vtz" -o "dm_$t.tif"
    "$PY" chk.py mapped_codes "dm_$t.vtz" "dm_$t.tif" "$istria" -3276.8 0.1 0.5
done
echo "   an Int16 GeoTIFF of codes with GDAL scale 10 (metres): MAX_Z_ERROR and --max-error bound metres"
"$PY" chk.py make_scaled kauai.tif s10.tif
"$VTZ" -q encode s10.tif -o s10_cli.vtz --max-error 1
"$VTZ" -q decode s10_cli.vtz -o s10_cli.tif
"$PY" chk.py scaled_bound s10.tif s10_cli.tif 1
"$VTZ" -q encode s10.tif -o s10_cli25.vtz --max-error 25
"$VTZ" -q decode s10_cli25.vtz -o s10_cli25.tif
"$PY" chk.py scaled_bound s10.tif s10_cli25.tif 25
gdal_translate -q -of VTZ -co MAX_Z_ERROR=1 s10.tif s10_gdal1.vtz
"$PY" chk.py scaled_bound s10.tif s10_gdal1.vtz 1
gdal_translate -q -of VTZ -co MAX_Z_ERROR=25 s10.tif s10_gdal.vtz
"$PY" chk.py scaled_bound s10.tif s10_gdal.vtz 25
"$VTZ" info s10_gdal.vtz | grep -q "value = 0 + 10 \* code" || { echo "FAIL: vtz info does not show the scale" >&2; exit 1; }
ok "vtz info names the scale"
echo "   64-bit integers: stored as Float64 only when every value is exact (|v| <= 2^53)"
"$PY" chk.py make_int64 u64_big.tif u 1
"$PY" chk.py make_int64 i64_big.tif i 1
"$PY" chk.py make_int64 u64_small.tif u 0
expect_error "not exactly a Float64" gdal_translate -q -of VTZ -co LOSSLESS=YES u64_big.tif bad.vtz
[ ! -e bad.vtz ] || { echo "FAIL: a refused UInt64 copy left bad.vtz" >&2; exit 1; }
expect_error "not exactly a Float64" gdal_translate -q -of VTZ -co MAX_Z_ERROR=1 i64_big.tif bad.vtz
gdal_translate -q -of VTZ -co LOSSLESS=YES u64_small.tif u64_small.vtz 2>/dev/null
"$PY" chk.py same_values u64_small.tif u64_small.vtz
echo "   an internal mask band and no nodata: masked samples are nodata in the copy"
for t in f i; do
    "$PY" chk.py make_masked kauai.tif "masked_$t.tif" $t
    gdal_translate -q -of VTZ "masked_$t.tif" "masked_$t.vtz"
    "$PY" chk.py masked "masked_$t.tif" "masked_$t.vtz"
done

echo "all GDAL plugin checks passed"
