"""The speed table of benches/residual_speed.sh: vtz's lines (examples/residual_speed JSON,
prefixed T1/T2 for the thread count) and the peers harness's CSV -> Markdown, M samples/s
(medians of 3 runs for vtz, best of 3 for the peers, as the harness reports them)."""
import csv, json, os, sys

vtz, files = {}, {}
for line in open(sys.argv[1]):
    if not line.startswith(("T1 ", "T2 ")):
        continue
    t, js = line.split(" ", 1)
    j = json.loads(js)
    name = os.path.basename(j["file"])[:-4]
    files[name] = j["file"]
    vtz[(name, j["bound"], j["effort"], t)] = j
peers = {}
for r in csv.DictReader(open(sys.argv[2])):
    b = "1" if r["target"] == "abs 1" else r["target"]
    peers[(r["raster"], b, r["codec"])] = r
print("| raster | request | vtz lane enc / dec | vtz lane dec, 2 threads | vtz fast enc / dec | vtz default enc / dec | "
      "SZ3 enc / dec | LERC enc / dec | JPEG XL e7 enc / dec | pcodec enc / dec | lane / fast / default bytes |")
print("|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
for name, path in files.items():
    samples = os.path.getsize(path) // 4
    for b in ["lossless", "1", "1%"]:
        f1, c1, f2, g1 = (vtz.get((name, b, e, t)) for e, t in [("1", "T1"), ("5", "T1"), ("1", "T2"), ("2", "T1")])
        if not (f1 and c1 and f2 and g1):
            continue

        def peer(codec):
            r = peers.get((name, b, codec))
            if not r:
                return ""
            return f"{samples / float(r['enc_s']) / 1e6:.0f} / {samples / float(r['dec_s']) / 1e6:.0f}"

        print(f"| {name} | {b} | {f1['encode_msps_median']:.1f} / {f1['decode_msps_median']:.1f} | "
              f"{f2['decode_msps_median']:.1f} | {g1['encode_msps_median']:.1f} / {g1['decode_msps_median']:.1f} | "
              f"{c1['encode_msps_median']:.1f} / {c1['decode_msps_median']:.1f} | "
              f"{peer('sz3')} | {peer('lerc')} | {peer('jxl')} | {peer('pcodec')} | "
              f"{f1['bytes'] / c1['bytes']:.3f} / {g1['bytes'] / c1['bytes']:.3f} / 1 |")
