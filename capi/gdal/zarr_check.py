"""GDAL reads a Zarr store that vtz's Python codec wrote (the plugin's "vtz" decompressor).

    python zarr_check.py RASTER WORK_DIR

With a Python that has the vtz wheel, zarr and numcodecs: writes RASTER as a Zarr format 2
array with `vtz.numcodecs.Vtz(max_error=1)` as its compressor (chunks 500 x 500, so edge
chunks are partial), converts it with `gdal_translate` (GDAL_DRIVER_PATH must name the
plugin's folder) and checks that GDAL's samples are exactly the ones zarr-python decodes,
and within 1 of the source; a chunk that decodes to more samples than its chunk holds is
an error, not a crash. Exits 1 on any difference. A Zarr format 3 store (the
`vtz.zarr.VtzCodec` serializer) is tried too and its outcome printed: GDAL 3.6's Zarr V3
support follows an earlier draft of the specification than zarr-python 3 writes.
"""

import os
import subprocess
import sys

import numpy as np
import zarr

import vtz
import vtz.numcodecs
import vtz.zarr


def gdal_samples(src, work, name):
    out = os.path.join(work, name + ".tif")
    r = subprocess.run(
        ["gdal_translate", "-q", "-of", "GTiff", src, out], capture_output=True, text=True
    )
    if r.returncode != 0:
        return None, r.stderr.strip().splitlines()[-1:] or ["exit %d" % r.returncode]
    a, _ = vtz.read(out)
    return a, None


def main():
    raster, work = sys.argv[1], sys.argv[2]
    src, profile = vtz.read(raster)
    nodata = profile["nodata"]
    fill = nodata if nodata is not None else 0
    ok = True

    path2 = os.path.join(work, "v2.zarr")
    z = zarr.create_array(
        store=path2,
        shape=src.shape,
        chunks=(500, 500),
        dtype=src.dtype,
        zarr_format=2,
        compressors=vtz.numcodecs.Vtz(max_error=1, nodata=nodata),
        filters=None,
        fill_value=fill,
    )
    z[:] = src
    expect = zarr.open_array(path2, mode="r")[:]
    got, err = gdal_samples(path2, work, "v2")
    if got is None:
        print(f"FAIL: GDAL could not read the Zarr v2 store: {err}")
        return 1
    same = got.shape == expect.shape and np.array_equal(got, expect)
    valid = src != fill
    worst = int(np.max(np.abs(got[valid].astype(np.int64) - src[valid].astype(np.int64))))
    print(
        f"Zarr v2 + vtz compressor, {src.shape[1]} x {src.shape[0]} {src.dtype}, chunks 500:"
        f" GDAL == zarr-python: {same}; max error against the source: {worst}"
    )
    ok &= same and worst <= 1

    # A chunk that decodes to more samples than the chunk holds (a valid vtz stream of a
    # constant 1200 x 1200 raster in place of a 500 x 500 chunk): refused by the limit
    # GDAL's buffer sets, before anything is allocated; an error, not a crash.
    import shutil

    bad = os.path.join(work, "v2_bad.zarr")
    shutil.copytree(path2, bad)
    big = vtz.encode(np.zeros((1200, 1200), dtype=src.dtype), max_error=1)
    with open(os.path.join(bad, "0.0"), "wb") as f:
        f.write(big)
    r = subprocess.run(
        ["gdal_translate", "-q", "-of", "GTiff", bad, os.path.join(work, "bad.tif")],
        capture_output=True,
        text=True,
    )
    refused = r.returncode == 1 and "limit" in r.stderr
    print(f"an oversized chunk: exit {r.returncode}, {r.stderr.strip().splitlines()[:1]}")
    ok &= refused

    path3 = os.path.join(work, "v3.zarr")
    z3 = zarr.create_array(
        store=path3,
        shape=src.shape,
        chunks=(500, 500),
        dtype=src.dtype,
        serializer=vtz.zarr.VtzCodec(max_error=1, nodata=nodata),
        compressors=None,
        fill_value=fill,
    )
    z3[:] = src
    got3, err3 = gdal_samples(path3, work, "v3")
    if got3 is None:
        print(f"Zarr v3 + VtzCodec: GDAL does not read it: {err3[0] if err3 else '?'}")
    else:
        print(f"Zarr v3 + VtzCodec: GDAL == zarr-python: {np.array_equal(got3, z3[:])}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
