"""benches/web/native.py OUTDIR [ARCHIVE...]: native reference for the per-tile decode, with
the CLI: every finest-zoom tile of each vtz archive written to a .vtz file and decoded by
`target/ci/vtz decode --threads 1 -o X.f32` (5 runs, median), minus the median of the same
for the archive's z0 tile (an almost empty 512² tile: process start, output write). Rough:
the CLI's process start is a few ms. Prints JSON."""
import json, os, statistics, subprocess, sys, tempfile, time
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import pmt

out = sys.argv[1]
names = sys.argv[2:] or ['kauai512.vtz-0.1', 'srtm1_512.vtz-0.1']
vtz = os.environ.get('VTZ', os.path.join(os.path.dirname(__file__), '..', '..', 'target', 'ci', 'vtz'))
res = {}
with tempfile.TemporaryDirectory(dir='/dev/shm' if os.path.isdir('/dev/shm') else None) as tmp:
    def run(b, reps=5):
        open(f'{tmp}/t.vtz', 'wb').write(b)
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            subprocess.run([vtz, 'decode', '--threads', '1', '-q', '-f', f'{tmp}/t.vtz', '-o', f'{tmp}/t.f32'], check=True)
            ts.append((time.perf_counter() - t0) * 1e3)
        return statistics.median(ts)
    for name in names:
        h, tiles, _ = pmt.read(os.path.join(out, name + '.pmtiles'))
        base = run(tiles[0], 9)
        fin = [run(b) for i, b in sorted(tiles.items()) if pmt.zoom_of(i) == h['max_zoom']]
        res[name] = dict(baseline_z0_ms=base, finest_median_ms=statistics.median(fin),
                         finest_minus_baseline_ms=statistics.median(fin) - base, n_finest=len(fin))
        print(name, res[name], file=sys.stderr)
print(json.dumps(res, indent=1))
