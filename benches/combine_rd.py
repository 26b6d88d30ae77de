#!/usr/bin/env python3
"""Merge a `vtz rd --csv` table with a peers harness CSV (../shared/tools/peers) into one
markdown table: per raster and max-error bound (% of the value range), the bits per sample
of every vtz method and the lowest bits per sample of every peer codec among its rows whose
achieved max error is within the bound (so codecs that are not error-bounded, like JPEG 2000
9/7, count only where they happen to meet it).

    python3 benches/combine_rd.py VTZ.csv PEERS.csv > table.md
"""
import csv
import sys
from collections import defaultdict

VTZ = ["best", "sibson", "grid", "haar", "fis"]
PEERS = [("sz3", "SZ3"), ("sperr-native", "SPERR"), ("lerc", "LERC"), ("j2k", "JPEG 2000"),
         ("jpegls", "JPEG-LS"), ("delatin", "Delatin"), ("haar", "peers Haar")]


def stem(name):
    return name.rsplit("/", 1)[-1].split(".")[0]


def main(vtz_csv, peers_csv):
    vtz = {}
    for r in csv.DictReader(open(vtz_csv)):
        if r["bps"]:
            vtz[(stem(r["file"]), r["method"], float(r["bound"].rstrip("%")))] = float(r["bps"])
    peers = defaultdict(list)
    amp = {}
    for r in csv.DictReader(open(peers_csv)):
        if r["codec"] == "codec" or not r["bps"]:
            continue
        peers[(r["raster"], r["codec"])].append((float(r["bps"]), float(r["max_pct"] or 0)))
    rasters = sorted({k[0] for k in vtz})
    bounds = sorted({k[2] for k in vtz})
    head = ["raster", "bound"] + [f"vtz {m}" for m in VTZ] + [p[1] for p in PEERS] + ["best peer / vtz best"]
    print("| " + " | ".join(head) + " |")
    print("|---|--:|" + "--:|" * (len(head) - 2))
    for ras in rasters:
        for b in bounds:
            row = [ras, f"{b:g} %"]
            for m in VTZ:
                v = vtz.get((ras, m, b))
                row.append(f"{v:.4f}" if v is not None else "—")
            best_peer = None
            for key, _ in PEERS:
                ok = [bps for bps, mp in peers.get((ras, key), []) if mp <= b * (1 + 1e-9)]
                if ok:
                    v = min(ok)
                    row.append(f"{v:.4f}")
                    best_peer = v if best_peer is None else min(best_peer, v)
                else:
                    row.append("—")
            vb = vtz.get((ras, "best", b))
            row.append(f"{best_peer / vb:.2f}" if vb and best_peer else "—")
            print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
