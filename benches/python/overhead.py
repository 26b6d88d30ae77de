"""Python overhead over the Rust library: the same encode and decode of a 1201² raster,
in-process on both sides, runs interleaved (Rust, Python, Rust, Python, …), medians.

    python benches/python/overhead.py corpus/srtm3_N22W160_kauai.hgt --max-error 1 --rounds 5

Needs the wheel installed (`pip install python/dist/vtz-*.whl`) and builds the example
`codec_timing` with cargo. Writes a JSON line per codec call kind and a Markdown table.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np
import vtz

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def rust_runs(exe, path, bound, runs):
    out = subprocess.run([exe, path, str(bound), str(runs)], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def py_runs(path, bound, runs):
    a, prof = vtz.read(path)
    nodata = prof["nodata"]
    te, td, size = [], [], 0
    for _ in range(runs):
        t = time.perf_counter()
        b = vtz.encode(a, max_error=bound, nodata=nodata)
        te.append(time.perf_counter() - t)
        t = time.perf_counter()
        d = vtz.decode(b)
        td.append(time.perf_counter() - t)
        size = len(b)
        assert d.shape == a.shape
    return {"encode_s": te, "decode_s": td, "bytes": size}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("raster")
    ap.add_argument("--max-error", type=float, default=1.0)
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds")
    ap.add_argument("--runs", type=int, default=3, help="calls per round")
    ap.add_argument("--md", help="write the Markdown table here")
    a = ap.parse_args()
    subprocess.run(
        ["cargo", "build", "--release", "--quiet", "--example", "codec_timing"], cwd=ROOT, check=True
    )
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    exe = os.path.join(target, "release", "examples", "codec_timing")
    r = {"encode_s": [], "decode_s": []}
    p = {"encode_s": [], "decode_s": []}
    sizes = set()
    for _ in range(a.rounds):
        for side, fn in (("rust", rust_runs), ("python", None)):
            res = rust_runs(exe, a.raster, a.max_error, a.runs) if side == "rust" else py_runs(
                a.raster, a.max_error, a.runs
            )
            dst = r if side == "rust" else p
            dst["encode_s"] += res["encode_s"]
            dst["decode_s"] += res["decode_s"]
            sizes.add(res["bytes"])
    rows = []
    for k in ("encode_s", "decode_s"):
        mr, mp = statistics.median(r[k]), statistics.median(p[k])
        rows.append((k[:-2], mr, mp, mp / mr - 1))
        print(json.dumps({"call": k[:-2], "rust_median_s": mr, "python_median_s": mp,
                          "overhead": mp / mr - 1, "runs": len(r[k]), "bytes": sorted(sizes)}))
    md = [f"`{os.path.basename(a.raster)}`, max error {a.max_error}, {len(r['encode_s'])} calls each "
          f"(interleaved), bytes {sorted(sizes)}", "",
          "| call | Rust median s | Python median s | overhead |", "|---|--:|--:|--:|"]
    md += [f"| {c} | {x:.4f} | {y:.4f} | {o * 100:+.1f} % |" for c, x, y, o in rows]
    text = "\n".join(md)
    print(text)
    if a.md:
        with open(a.md, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
