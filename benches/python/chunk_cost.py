"""In-process codec cost on the chunks of the Dask mosaic (the 3600² SRTM1 tile, 900² chunks,
1 m): CPU seconds (time.process_time, one thread) to encode and to decode every chunk, per codec,
rounds interleaved (each round starts with another codec); medians of the rounds. No Dask, no
store: what the codec itself costs, steadier than wall time on a shared machine.

    python chunk_cost.py MOSAIC.vrt [ROUNDS]

MOSAIC.vrt: the VRT dask_mosaic.py builds in its --out-dir (mosaic.vrt)."""
import statistics, sys, time
import numpy as np, vtz, rioxarray
from imagecodecs import lerc_encode, lerc_decode
da = rioxarray.open_rasterio(sys.argv[1]).squeeze()
a = np.ascontiguousarray(da.values)
C = 900
chunks = [np.ascontiguousarray(a[i:i + C, j:j + C])
          for i in range(0, a.shape[0], C) for j in range(0, a.shape[1], C)]
codecs = {
    "vtz-residual-e1": (lambda c: vtz.encode(c, max_error=1, nodata=-32768, method="residual", effort=1, threads=1), lambda b: vtz.decode(b, threads=1)),
    "vtz-residual-e5": (lambda c: vtz.encode(c, max_error=1, nodata=-32768, method="residual", threads=1), lambda b: vtz.decode(b, threads=1)),
    "lerc": (lambda c: lerc_encode(c, level=1.0), lambda b: lerc_decode(b)),
}
rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
res = {k: {"enc": [], "dec": [], "bytes": 0} for k in codecs}
for r in range(rounds):
    names = list(codecs)
    names = names[r % len(names):] + names[:r % len(names)]
    for k in names:
        enc, dec = codecs[k]
        t = time.process_time(); bs = [enc(c) for c in chunks]; te = time.process_time() - t
        t = time.process_time(); outs = [dec(b) for b in bs]; td = time.process_time() - t
        for c, o in zip(chunks, outs):
            assert np.abs(o.astype(int) - c.astype(int)).max() <= 1
        res[k]["enc"].append(te); res[k]["dec"].append(td); res[k]["bytes"] = sum(len(b) for b in bs)
        print(r, k, f"enc {te:.3f} dec {td:.3f}", flush=True)
L = res["lerc"]
le, ld = statistics.median(L["enc"]), statistics.median(L["dec"])
print("| codec | bytes | encode CPU s | decode CPU s | encode / LERC | decode / LERC | bytes / LERC |")
print("|---|--:|--:|--:|--:|--:|--:|")
for k, v in res.items():
    e, d = statistics.median(v["enc"]), statistics.median(v["dec"])
    print(f"| {k} | {v['bytes']:,} | {e:.3f} | {d:.3f} | {e/le:.1f}x | {d/ld:.1f}x | {v['bytes']/L['bytes']:.3f} |")
