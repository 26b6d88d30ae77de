"""benches/web/native.py OUTDIR [ARCHIVE...]: the native reference for the per-tile decode:
every finest-zoom tile of each vtz archive (default kauai512.vtz-0.1, srtm1_512.vtz-0.1)
written to a .vtz file and decoded in process on one thread by web/wasm's native_bench
example (the same decode and f32 conversion as the wasm's vtz_decode; build it with
`cargo build --release --example native_bench --manifest-path web/wasm/Cargo.toml`, or point
VTZ_NATIVE_BENCH at a build). Median over tiles of each tile's median of 7 decodes.
Prints JSON ({} when there is no native_bench)."""
import json, os, re, statistics, subprocess, sys, tempfile
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import pmt

out = sys.argv[1]
names = sys.argv[2:] or ['kauai512.vtz-0.1', 'srtm1_512.vtz-0.1']
root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..')
exe = os.environ.get('VTZ_NATIVE_BENCH', os.path.join(root, 'web/wasm/target/release/examples/native_bench'))
res = {}
if not os.path.exists(exe):
    print(f'native.py: no {exe}: skipped', file=sys.stderr)
else:
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            h, tiles, _ = pmt.read(os.path.join(out, name + '.pmtiles'))
            files = []
            for i, b in sorted(tiles.items()):
                if pmt.zoom_of(i) == h['max_zoom']:
                    files.append(f'{tmp}/{i}.vtz'); open(files[-1], 'wb').write(b)
            txt = subprocess.run([exe, '--threads', '1', '--reps', '8', *files], check=True,
                                 capture_output=True, text=True).stdout
            med = [float(m) for m in re.findall(r'median ([\d.]+) ms', txt)]
            assert len(med) == len(files), txt
            res[name] = dict(exe=exe, n_finest=len(files), finest_median_ms=statistics.median(med),
                             finest_min_ms=min(med), finest_max_ms=max(med))
            print(name, res[name], file=sys.stderr)
print(json.dumps(res, indent=1))
