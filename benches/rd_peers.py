#!/usr/bin/env python3
"""Merge `benches/rd_peers.sh` (vtz best, every decode checked with rastercmp) with the peers
harness CSV (../shared/tools/peers, same rasters, same bounds) into the markdown table of
benches/README.md: per raster and bound, vtz best's bits per sample beside the lowest bits
per sample of each peer among its rows whose *achieved* max error is within the bound
(lossless: its lossless rows), and vtz / best peer.

    python3 benches/rd_peers.py vtz21.csv peers21.csv > table.md

Lossy cells compare with the error-bounded peers (SZ3, SPERR, LERC, JPEG-LS, ZFP); the
lossless cells with every peer's lossless rows (JPEG XL effort 7 and pcodec included).
"""
import csv
import math
import sys
from collections import defaultdict

BOUNDED = [("sz3", "SZ3"), ("sperr-native", "SPERR"), ("lerc", "LERC"), ("jpegls", "JPEG-LS"), ("zfp", "ZFP")]
LOSSLESS = BOUNDED + [("jxl", "JPEG XL"), ("pcodec", "pcodec")]
TARGETS = ["lossless", "0.5", "1", "2", "5", "0.01%", "0.03%", "0.1%", "0.3%", "1%", "3%", "10%"]


def main(vtz_csv, peers_csv):
    vtz = {}
    for r in csv.DictReader(open(vtz_csv)):
        vtz[(r["raster"], r["target"])] = r
    peers = defaultdict(list)
    for r in csv.DictReader(open(peers_csv)):
        if r["codec"] == "codec" or not r["bps"]:
            continue
        peers[(r["raster"], r["codec"])].append(
            (float(r["bps"]), float(r["max_err"] or 0), r["lossless"] == "True"))
    rasters = sorted({k[0] for k in vtz})
    head = ["raster", "bound", "vtz best", "method"] + [p[1] for p in LOSSLESS] + ["vtz / best peer"]
    print("| " + " | ".join(head) + " |")
    print("|---|--:|--:|---|" + "--:|" * (len(LOSSLESS) + 1))
    ratios = defaultdict(list)
    checks = [0, 0]
    for ras in rasters:
        for t in TARGETS:
            v = vtz.get((ras, t))
            if not v:
                continue
            b = float(v["bound"])
            checks[0] += 1
            checks[1] += v["check"] == "yes"
            cells, best = [], None
            for key, _ in LOSSLESS:
                rows = peers.get((ras, key), [])
                if t == "lossless":
                    ok = [bps for bps, _, ll in rows if ll]
                elif key in dict(BOUNDED):
                    ok = [bps for bps, me, _ in rows if me <= b * (1 + 1e-9)]
                else:
                    ok = []
                m = min(ok) if ok else None
                cells.append(f"{m:.3f}" if m is not None else "")
                if m is not None and (best is None or m < best):
                    best = m
            bps = float(v["bps"])
            ratio = bps / best if best else None
            if ratio:
                ratios[t].append(ratio)
            flag = "" if v["check"] == "yes" else " **bound broken**"
            label = "lossless" if t == "lossless" else (t if t.endswith("%") else f"{t} m")
            tail = f" | {ratio:.2f} |" if ratio else " | – |"
            print(f"| {ras} | {label} | {bps:.3f}{flag} | {v['method']} | " + " | ".join(cells) + tail)
    print()
    print(f"{checks[1]} of {checks[0]} vtz decodes checked within their bound by rastercmp.py.")
    print()
    print("| bound | rasters | geometric mean vtz / best peer | best | worst | cells ≤ 0.9 | cells ≤ 1.0 |")
    print("|---|--:|--:|--:|--:|--:|--:|")
    for t in TARGETS:
        r = ratios.get(t)
        if not r:
            continue
        g = math.exp(sum(map(math.log, r)) / len(r))
        label = "lossless" if t == "lossless" else (t if t.endswith("%") else f"{t} m")
        print(f"| {label} | {len(r)} | {g:.3f} | {min(r):.2f} | {max(r):.2f} | "
              f"{sum(x <= 0.9 for x in r)} | {sum(x <= 1.0 for x in r)} |")


if __name__ == "__main__":
    main(*sys.argv[1:3])
