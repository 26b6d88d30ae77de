#!/usr/bin/env python3
"""Flat regions under every method and bound: how many samples of the flat regions change.

A flat region here is computed independently of vtz: a 4-connected component of one exact
value among valid samples with at least 1024 samples, minus the samples that touch another
such component of a different value (vtz's rule, spec/FORMAT.md "Flat section"). Also
counts every sample whose source is exactly the sea level 0 and that decodes elsewhere
(the issue's Kauai measure, which includes small zero patches outside any region).

    python3 benches/flat_regions.py VTZ RASTER.f32... [--methods best,residual,sibson,grid]
"""
import json, os, subprocess, sys, tempfile
import numpy as np
from scipy import ndimage

args = sys.argv[1:]
methods = ["best", "residual", "sibson", "grid"]
if "--methods" in args:
    i = args.index("--methods"); methods = args[i + 1].split(","); del args[i:i + 2]
vtz, rasters = args[0], args[1:]
BOUNDS = ["0.5", "1", "2", "5", "0.1%", "1%", "10%"]


def flat_mask(a, valid):
    out = np.zeros(a.shape, bool)
    labels = np.zeros(a.shape, np.int64)
    nxt = 0
    for v in np.unique(a[valid]):
        lab, n = ndimage.label(valid & (a == v))
        if n == 0:
            continue
        sizes = np.bincount(lab.ravel())
        big = sizes >= 1024
        big[0] = False
        keep = big[lab]
        labels[keep] = lab[keep] + nxt
        nxt += n
        out |= keep
    # drop samples touching a different region
    touch = np.zeros(a.shape, bool)
    for sl_a, sl_b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                       ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
        la, lb = labels[sl_a], labels[sl_b]
        t = (la > 0) & (lb > 0) & (la != lb)
        touch[sl_a] |= t
        touch[sl_b] |= t
    return out & ~touch


print("raster,method,bound,flat_samples,flat_changed,zero_samples,zero_changed,bytes,method_written")
with tempfile.TemporaryDirectory() as tmp:
    for path in rasters:
        j = json.load(open(path[:-4] + ".json"))
        a = np.fromfile(path, "<f4").reshape(j["height"], j["width"]).astype(np.float64)
        valid = np.isfinite(a)
        if j.get("nodata") is not None:
            valid &= a != j["nodata"]
        flat = flat_mask(a, valid)
        zero = valid & (a == 0)
        name = os.path.basename(path)[:-4]
        for m in methods:
            for b in BOUNDS:
                out = os.path.join(tmp, "x.vtz")
                r = subprocess.run([vtz, "encode", path, "-o", out, "-f", "--json", "-q",
                                    "--method", m, "--max-error", b], capture_output=True, text=True)
                if r.returncode != 0:
                    print(f"{name},{m},{b},,,,,,{r.stderr.strip()[:60]}")
                    continue
                meta = json.loads(r.stdout)
                subprocess.run([vtz, "decode", out, "-o", os.path.join(tmp, "x.f32"), "-f", "-q"], check=True)
                d = np.fromfile(os.path.join(tmp, "x.f32"), "<f4").reshape(a.shape).astype(np.float64)
                print(f"{name},{m},{b},{flat.sum()},{(flat & (d != a)).sum()},{zero.sum()},"
                      f"{(zero & (d != a)).sum()},{meta['bytes']},{meta['method']}", flush=True)
