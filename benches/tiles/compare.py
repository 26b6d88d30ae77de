#!/usr/bin/env python3
# Requires (Python 3.11, the venv /work/venv): numpy==2.4.6, tifffile==2026.3.3,
# imagecodecs==2026.3.6 (tifffile decodes Deflate/LZW chunks through it when present).
"""Streaming comparison of two same-size single-band GeoTIFFs, band of rows by band of rows.

Usage: compare.py SRC.tif DECODED.tif --bound E [--at X,Y] [--band ROWS] [--json]

E is in data units, or "P%" for P % of SRC's valid range (max − min; one extra streaming
pass). With --at X,Y, DECODED is a window (e.g. `vtz decode --window X,Y,W,H`) and is compared
with SRC's samples at columns X..X+W−1, rows Y..Y+H−1 (a percentage bound still takes the
range of the whole of SRC). Neither file is read whole: each is read chunk row by chunk row (a row of tiles, or a
strip) straight from its TIFF chunks, and only the chunk rows that overlap the current band
are kept, so memory stays at a few bands whatever the image height (peak RSS ~250 MB,
Python and its libraries included, for the 20000² int16 mosaic at the default band of 256
rows; --band 64 lowers it). A file stored as one huge strip is the exception: its strip is
decoded whole.

A sample is valid when it is not the file's GDAL_NODATA value and not NaN. The two files must
agree on validity sample for sample (a valid sample decoded as nodata, or the reverse, is a
failure); over the valid samples |SRC − DECODED| ≤ E must hold. Prints the sample count, the
valid count, max error (and where), RMSE and the mask mismatches; exits 0 when everything
holds, 1 when the bound or the mask fails or the files disagree in size, 2 on usage errors.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
import tifffile


class RowReader:
    """Rows [y0, y1) of a single-band TIFF's first image, decoded chunk row by chunk row."""

    def __init__(self, path: str):
        self.path = path
        self.tif = tifffile.TiffFile(path)
        p = self.tif.pages.first
        if p.samplesperpixel != 1:
            raise SystemExit(f"{path}: {p.samplesperpixel} samples per pixel (want 1)")
        if p.imagedepth != 1:
            raise SystemExit(f"{path}: volumetric TIFF (depth {p.imagedepth})")
        self.page = p
        self.height, self.width = int(p.imagelength), int(p.imagewidth)
        self.dtype = p.dtype
        tag = p.tags.get(42113)  # GDAL_NODATA
        nd = None
        if tag is not None:
            txt = str(tag.value).strip().strip("\x00")
            if txt and txt.lower() != "nan":
                nd = float(txt)
        self.nodata = nd
        if p.is_tiled:
            self.seg_h, self.seg_w = int(p.tilelength), int(p.tilewidth)
        else:
            rps = int(p.rowsperstrip) if p.rowsperstrip else self.height
            self.seg_h, self.seg_w = min(rps, self.height), self.width
        self.nx = -(-self.width // self.seg_w)
        self.ny = -(-self.height // self.seg_h)
        if len(p.dataoffsets) != self.nx * self.ny:
            raise SystemExit(f"{path}: {len(p.dataoffsets)} chunks, expected {self.nx * self.ny}")
        self.cache: dict[int, np.ndarray] = {}
        self.fh = self.tif.filehandle

    def _chunk_row(self, i: int) -> np.ndarray:
        y0 = i * self.seg_h
        h = min(self.seg_h, self.height - y0)
        out = np.empty((h, self.width), self.dtype)
        p = self.page
        for j in range(self.nx):
            idx = i * self.nx + j
            x0 = j * self.seg_w
            w = min(self.seg_w, self.width - x0)
            off, cnt = p.dataoffsets[idx], p.databytecounts[idx]
            if cnt == 0:  # sparse chunk: GDAL reads it as nodata (or 0)
                out[:, x0:x0 + w] = self.nodata if self.nodata is not None else 0
                continue
            self.fh.seek(off)
            data = self.fh.read(cnt)
            seg, _, _ = p.decode(data, idx)  # (depth, length, width, samples); tiles padded
            seg = np.asarray(seg)
            seg = seg.reshape(seg.shape[-3], seg.shape[-2])
            out[:, x0:x0 + w] = seg[:h, :w]
        return out

    def rows(self, y0: int, y1: int) -> np.ndarray:
        first, last = y0 // self.seg_h, (y1 - 1) // self.seg_h
        for k in [k for k in self.cache if k < first]:
            del self.cache[k]
        parts = []
        for i in range(first, last + 1):
            if i not in self.cache:
                self.cache[i] = self._chunk_row(i)
            c = self.cache[i]
            cy0 = i * self.seg_h
            parts.append(c[max(y0, cy0) - cy0:min(y1, cy0 + c.shape[0]) - cy0])
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def valid(self, a: np.ndarray) -> np.ndarray:
        v = np.ones(a.shape, bool)
        if a.dtype.kind == "f":
            v &= ~np.isnan(a)
        if self.nodata is not None:
            v &= a != np.asarray(self.nodata).astype(a.dtype)
        return v

    def close(self):
        self.tif.close()


def bands(height: int, band: int):
    for y0 in range(0, height, band):
        yield y0, min(height, y0 + band)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src")
    ap.add_argument("decoded")
    ap.add_argument("--bound", required=True, help="max abs error E in data units, or P%% of "
                    "SRC's valid range")
    ap.add_argument("--at", help="X,Y: DECODED is the window of SRC with this upper-left corner")
    ap.add_argument("--band", type=int, default=256, help="rows per band (default 256)")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    a = ap.parse_args()
    if a.band < 1:
        ap.error("--band must be positive")
    try:
        pct = a.bound.endswith("%")
        bval = float(a.bound[:-1] if pct else a.bound)
    except ValueError:
        ap.error(f"--bound {a.bound!r} is not a number or a percentage")
    if not (math.isfinite(bval) and bval >= 0):
        ap.error("--bound must be finite and non-negative")

    ax, ay = 0, 0
    if a.at:
        try:
            ax, ay = (int(v) for v in a.at.split(","))
        except ValueError:
            ap.error(f"--at {a.at!r} is not X,Y")
        if ax < 0 or ay < 0:
            ap.error("--at must not be negative")
    t0 = time.perf_counter()
    try:
        A, B = RowReader(a.src), RowReader(a.decoded)
    except (OSError, ValueError, IndexError, tifffile.TiffFileError) as e:
        print(f"compare.py: cannot read the inputs as TIFF: {e}", file=sys.stderr)
        return 2
    res = {"src": a.src, "decoded": a.decoded, "width": B.width, "height": B.height}
    if a.at:
        res["at_xy"] = [ax, ay]
    if ax + B.width > A.width or ay + B.height > A.height or (
            not a.at and (A.width, A.height) != (B.width, B.height)):
        msg = (f"size differs: {A.width}x{A.height} vs {B.width}x{B.height}" if not a.at else
               f"window {B.width}x{B.height} at ({ax}, {ay}) is not inside {A.width}x{A.height}")
        print(json.dumps({**res, "ok": False, "error": msg}) if a.json else f"FAIL: {msg}")
        return 1

    vmin, vmax = math.inf, -math.inf
    if pct:
        for y0, y1 in bands(A.height, a.band):
            x = A.rows(y0, y1)
            v = x[A.valid(x)]
            if v.size:
                vmin, vmax = min(vmin, float(v.min())), max(vmax, float(v.max()))
        A.cache.clear()
        bound = bval / 100.0 * (vmax - vmin) if vmax >= vmin else 0.0
    else:
        bound = bval

    n_valid = 0
    sse = 0.0
    max_err, max_at = 0.0, None
    over = 0
    only_src, only_dec = 0, 0
    first_mask_bad = None
    for y0, y1 in bands(B.height, a.band):
        x, y = A.rows(ay + y0, ay + y1)[:, ax:ax + B.width], B.rows(y0, y1)
        va, vb = A.valid(x), B.valid(y)
        bad_a, bad_b = va & ~vb, ~va & vb
        ca, cb = int(bad_a.sum()), int(bad_b.sum())
        if (ca or cb) and first_mask_bad is None:
            r, c = np.argwhere(bad_a | bad_b)[0]
            first_mask_bad = [int(ax + c), int(ay + y0 + r)]
        only_src += ca
        only_dec += cb
        both = va & vb
        d = np.abs(x.astype(np.float64) - y.astype(np.float64))
        d[~both] = 0.0
        n_valid += int(both.sum())
        sse += float(np.dot(d.ravel(), d.ravel()))
        over += int((d > bound).sum())
        k = int(np.argmax(d))
        if d.flat[k] > max_err:
            max_err = float(d.flat[k])
            max_at = [ax + k % B.width, ay + y0 + k // B.width]
    A.close()
    B.close()
    rmse = math.sqrt(sse / n_valid) if n_valid else 0.0
    ok = over == 0 and only_src == 0 and only_dec == 0
    res.update({
        "samples": B.width * B.height, "valid": n_valid, "bound": bound,
        "bound_arg": a.bound, "max_error": max_err, "max_error_at_xy": max_at, "rmse": rmse,
        "over_bound": over, "valid_in_src_only": only_src, "valid_in_decoded_only": only_dec,
        "first_mask_mismatch_xy": first_mask_bad, "ok": ok,
        "seconds": round(time.perf_counter() - t0, 3),
    })
    if pct:
        res["src_range"] = [vmin, vmax]
    if a.json:
        print(json.dumps(res))
    else:
        where = f" at ({ax}, {ay})" if a.at else ""
        print(f"{a.src}{where} vs {a.decoded}: {B.width}x{B.height} = {res['samples']} samples, "
              f"{n_valid} valid on both sides")
        if pct:
            print(f"src valid range {vmin:g} .. {vmax:g}; bound {a.bound} = {bound:g}")
        print(f"max error {max_err:g} at (x, y) = {max_at}; RMSE {rmse:.6g}; bound {bound:g}: "
              f"{over} samples over it")
        print(f"nodata mask: {only_src} valid only in src, {only_dec} valid only in decoded"
              + (f" (first at (x, y) = {first_mask_bad})" if first_mask_bad else ""))
        print(("OK" if ok else "FAIL") + f" ({res['seconds']:.1f} s)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
