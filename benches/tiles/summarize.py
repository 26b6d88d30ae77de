#!/usr/bin/env python3
# Requires (Python 3.11, the venv /work/venv): numpy==2.4.6 (standard library otherwise).
"""Markdown tables for benches/tiles/run.sh from its raw rows.

Usage: summarize.py ROWS.tsv RESULTS.jsonl PEERS_DIR BASE_THREADS

ROWS.tsv: one timed command a line (kind, input, samples, variant, threads, run, wall_s,
maxrss_kb, out_bytes, status); RESULTS.jsonl: vtz encode --json reports and compare.py
verdicts; PEERS_DIR/peers_NAME.csv: the peers harness's CSVs. Medians over runs for vtz, the
harness's best-of-repeat for SZ3 and LERC.
"""

from __future__ import annotations

import csv
import glob
import json
import math
import os
import statistics
import sys

import numpy as np


def fmt(v, nd=3):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, float):
        if v == 0:
            return "0"
        if abs(v) >= 100:
            return f"{v:.0f}"
        return f"{v:.{nd}g}" if abs(v) < 1 else f"{v:.{nd}f}".rstrip("0").rstrip(".")
    return str(v)


def ratio(a, b):
    if a is None or b is None or not b:
        return None
    return a / b


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        out.append("| " + " | ".join(fmt(x) for x in r) + " |")
    return "\n".join(out)


def main() -> int:
    rows_path, results_path, peers_dir, base_t = sys.argv[1:5]
    rows = list(csv.DictReader(open(rows_path), delimiter="\t"))
    results = [json.loads(line) for line in open(results_path) if line.strip()]
    ok_rows = [r for r in rows if r["status"] == "ok"]

    # (kind, input, variant, threads) -> list of (wall, rss_kb, bytes)
    groups: dict[tuple, list] = {}
    samples: dict[str, int] = {}
    for r in ok_rows:
        key = (r["kind"], r["input"], r["variant"], r["threads"])
        groups.setdefault(key, []).append(
            (float(r["wall_s"]), int(r["maxrss_kb"]), int(r["out_bytes"])))
        if r["kind"] != "window":
            samples[r["input"]] = int(r["samples"])

    def med(kind, inp, var, t):
        g = groups.get((kind, inp, var, t))
        return statistics.median(x[0] for x in g) if g else None

    def rss_mb(kind, inp, var, t):
        g = groups.get((kind, inp, var, t))
        return max(x[1] for x in g) / 1024 if g else None

    encode_info = {(d["input"], d["variant"], d["threads"]): d
                   for d in results if d.get("type") == "encode"}
    checks = {d["label"]: d for d in results if d.get("type") == "compare"}

    combos = sorted({(k[1], k[2], k[3]) for k in groups if k[0] in ("encode", "decode")},
                    key=lambda c: (samples.get(c[0], 0), c[1], c[2]))
    out = []
    if combos:
        out.append("## Encode and decode (CLI wall time, median of the runs; peak RSS = max)\n")
        body = []
        for inp, var, t in combos:
            n = samples.get(inp)
            e, d = med("encode", inp, var, t), med("decode", inp, var, t)
            info = encode_info.get((inp, var, t), {})
            g = groups.get(("encode", inp, var, t)) or [(0, 0, None)]
            nbytes = info.get("bytes", g[-1][2])
            tag = f"{inp}.{var}.{t}"
            verdict = []
            for what in ("requested", "achieved"):
                c = checks.get(f"{tag} {what}")
                if c:
                    verdict.append(f"{what} {fmt(c['bound'])}: {'OK' if c['ok'] else 'FAIL'}")
            body.append([
                inp, n, var, t, len(groups.get(("encode", inp, var, t), [])), e,
                rss_mb("encode", inp, var, t), d, rss_mb("decode", inp, var, t),
                ratio(n, e * 1e6) if e else None, ratio(n, d * 1e6) if d else None,
                nbytes, (8 * nbytes / n) if nbytes and n else None, info.get("method", "–"),
                info.get("max_error"), "; ".join(verdict) or "–",
            ])
        out.append(table(["input", "samples", "variant", "T", "runs", "enc s", "enc MB",
                          "dec s", "dec MB", "enc M/s", "dec M/s", "bytes", "bits/sample",
                          "method", "max err", "compare.py"], body))

        # Size exponent over the SRTM1 sizes (same content family), per variant and T.
        out.append("\n## Growth with size (least squares of log time on log samples, SRTM1 "
                   "sizes only)\n")
        body = []
        for var in sorted({c[1] for c in combos}):
            for t in sorted({c[2] for c in combos}):
                pts = [(samples[c[0]], med("encode", *c), med("decode", *c),
                        rss_mb("encode", *c), rss_mb("decode", *c))
                       for c in combos if c[1] == var and c[2] == t and c[0].startswith("srtm1")]
                pts = [p for p in pts if p[1] and p[2]]
                if len(pts) < 2:
                    continue
                ln = np.log([p[0] for p in pts])
                fit = [float(np.polyfit(ln, np.log([p[i] for p in pts]), 1)[0]) for i in (1, 2, 3, 4)]
                body.append([var, t, len(pts), f"{min(p[0] for p in pts)}..{max(p[0] for p in pts)}",
                             *fit])
        if body:
            out.append(table(["variant", "T", "sizes", "samples", "enc exponent", "dec exponent",
                              "enc RSS exponent", "dec RSS exponent"], body))
            out.append("\n(1 = linear in the samples. The top-left crops are flat plain and the "
                       "full tile is mountains, so a % bound is a different absolute bound at "
                       "each size: content, not only size, moves these numbers.)")
        else:
            out.append("(fewer than two sizes measured)")

        # Threads.
        by_input: dict[tuple, dict] = {}
        for inp, var, t in combos:
            by_input.setdefault((inp, var), {})[t] = t
        body = []
        for (inp, var), ts in by_input.items():
            if len(ts) < 2:
                continue
            t0 = base_t if base_t in ts else sorted(ts)[0]
            for t in sorted(ts):
                if t == t0:
                    continue
                e0, e1 = med("encode", inp, var, t0), med("encode", inp, var, t)
                d0, d1 = med("decode", inp, var, t0), med("decode", inp, var, t)
                body.append([inp, var, f"{t0} → {t}", e0, e1, ratio(e0, e1), d0, d1, ratio(d0, d1),
                             rss_mb("encode", inp, var, t0), rss_mb("encode", inp, var, t),
                             rss_mb("decode", inp, var, t0), rss_mb("decode", inp, var, t)])
        if body:
            out.append("\n## Threads\n")
            out.append(table(["input", "variant", "T", "enc s", "enc s", "enc speedup", "dec s",
                              "dec s", "dec speedup", "enc MB", "enc MB", "dec MB", "dec MB"], body))

        # Tiled vs untiled.
        body = []
        for inp, var, t in combos:
            if var != "untiled" or (inp, "tiled", t) not in {(c[0], c[1], c[2]) for c in combos}:
                continue
            eu, et = med("encode", inp, "untiled", t), med("encode", inp, "tiled", t)
            du, dt = med("decode", inp, "untiled", t), med("decode", inp, "tiled", t)
            bu = (encode_info.get((inp, "untiled", t)) or {}).get("bytes")
            bt = (encode_info.get((inp, "tiled", t)) or {}).get("bytes")
            body.append([inp, t, eu, et, ratio(et, eu), du, dt, ratio(dt, du), bu, bt, ratio(bt, bu),
                         rss_mb("encode", inp, "untiled", t), rss_mb("encode", inp, "tiled", t)])
        if body:
            out.append("\n## Tiled vs untiled (same T)\n")
            out.append(table(["input", "T", "untiled enc s", "tiled enc s", "tiled ÷ untiled",
                              "untiled dec s", "tiled dec s", "tiled ÷ untiled", "untiled bytes",
                              "tiled bytes", "tiled ÷ untiled", "untiled enc MB", "tiled enc MB"],
                             body))

    # Windows.
    wins = sorted({(k[1], k[2]) for k in groups if k[0] == "window"},
                  key=lambda w: tuple(int(v) for v in w[1].split(",")))
    if wins:
        out.append("\n## Window decodes (a fresh `vtz decode --window` process each; median)\n")
        body = []
        for inp, pos in wins:
            g = groups[("window", inp, pos, "-")]
            full = [med("decode", inp, "tiled", c[2]) for c in combos if c[0] == inp and c[1] == "tiled"]
            full = [f for f in full if f]
            c = checks.get(f"window {inp} {pos}")
            body.append([inp, pos, len(g), statistics.median(x[0] for x in g),
                         max(x[1] for x in g) / 1024, min(full) if full else None,
                         ("OK" if c["ok"] else "FAIL") + f" (max err {fmt(c['max_error'])})" if c else "–"])
        out.append(table(["input", "x,y", "runs", "window s", "window MB", "full decode s",
                          "compare.py"], body))

    # Peers.
    peer: dict[tuple, dict] = {}
    bounds: dict[str, float] = {}
    for fn in sorted(glob.glob(os.path.join(peers_dir, "peers_*.csv")), key=os.path.getmtime):
        for r in csv.DictReader(open(fn)):
            if r["target"] == "lossless":
                continue
            peer[(r["raster"], r["codec"])] = r
            bounds[r["raster"]] = float(r["bound"])
    if peer:
        names = list(bounds)  # in the order run.sh ran them (SIZES)
        have_vtz = any(("encode", n, "tiled", base_t) in groups for n in names)

        def f(r, k):
            return float(r[k]) if r.get(k) not in (None, "") else None

        def n_of(name):
            if name in samples:
                return samples[name]
            r = peer.get((name, "sz3")) or peer.get((name, "lerc"))
            return round(8 * float(r["bytes"]) / float(r["bps"])) if r and float(r["bps"]) else None

        title = ("SZ3 and LERC at the same absolute bound (peers harness: codec time in one "
                 "process, no file I/O, single thread, best of its repeats")
        if have_vtz:
            title += f"; vtz: CLI wall time incl. reading and writing, median, tiled, T={base_t}"
        out.append(f"\n## {title})\n")
        body = []
        for n in names:
            s, lc = peer.get((n, "sz3"), {}), peer.get((n, "lerc"), {})
            ns = n_of(n)
            row = [n, ns, bounds[n]]
            ve, vd = med("encode", n, "tiled", base_t), med("decode", n, "tiled", base_t)
            vb = (encode_info.get((n, "tiled", base_t)) or {}).get("bytes")
            if have_vtz:
                row += [ve, vd]
            row += [f(s, "enc_s"), f(s, "dec_s"), f(lc, "enc_s"), f(lc, "dec_s")]
            if have_vtz:
                row += [ratio(ve, f(s, "enc_s")), ratio(vd, f(s, "dec_s")),
                        ratio(ve, f(lc, "enc_s")), ratio(vd, f(lc, "dec_s"))]
            else:
                row += [ratio(ns, (f(s, "enc_s") or 0) * 1e6), ratio(ns, (f(s, "dec_s") or 0) * 1e6),
                        ratio(ns, (f(lc, "enc_s") or 0) * 1e6), ratio(ns, (f(lc, "dec_s") or 0) * 1e6)]
            if have_vtz:
                row += [vb]
            row += [int(f(s, "bytes")) if s else None, int(f(lc, "bytes")) if lc else None,
                    f(s, "max_err"), f(lc, "max_err")]
            body.append(row)
        hdr = ["input", "samples", "abs bound"]
        if have_vtz:
            hdr += ["vtz enc s", "vtz dec s"]
        hdr += ["SZ3 enc s", "SZ3 dec s", "LERC enc s", "LERC dec s"]
        if have_vtz:
            hdr += ["enc vtz/SZ3", "dec vtz/SZ3", "enc vtz/LERC", "dec vtz/LERC", "vtz bytes"]
        else:
            hdr += ["SZ3 enc M/s", "SZ3 dec M/s", "LERC enc M/s", "LERC dec M/s"]
        hdr += ["SZ3 bytes", "LERC bytes", "SZ3 max err", "LERC max err"]
        out.append(table(hdr, body))
        fits = []
        for codec in ("sz3", "lerc"):
            pts = [(n_of(n), f(peer[(n, codec)], "enc_s"), f(peer[(n, codec)], "dec_s"))
                   for n in names if (n, codec) in peer]
            pts = [p for p in pts if p[0] and p[1] and p[2]]
            if len(pts) >= 2:
                ln = np.log([p[0] for p in pts])
                fits.append(f"{codec.upper()} enc {np.polyfit(ln, np.log([p[1] for p in pts]), 1)[0]:.2f}, "
                            f"dec {np.polyfit(ln, np.log([p[2] for p in pts]), 1)[0]:.2f}")
        if fits:
            out.append("\nGrowth exponents over these sizes (log-log least squares): "
                       + "; ".join(fits) + ".")

    bad = [r for r in rows if r["status"] != "ok"]
    badc = [c for c in checks.values() if not c["ok"]]
    if bad or badc:
        out.append("\n## Failures\n")
        for r in bad:
            out.append(f"- {r['kind']} {r['input']} {r['variant']} T={r['threads']} run {r['run']}: "
                       f"{r['status']}")
        for c in badc:
            out.append(f"- compare.py {c['label']}: max err {c.get('max_error')} vs bound "
                       f"{c.get('bound')}, {c.get('over_bound')} over, mask "
                       f"{c.get('valid_in_src_only')}/{c.get('valid_in_decoded_only')}"
                       + (f" ({c['error']})" if c.get("error") else ""))
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
