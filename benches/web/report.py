"""benches/web/report.py OUTDIR PREFIX: PREFIX.md and PREFIX.csv from OUTDIR's sizes.json
(bench.py), decode.json (decode.mjs, Chromium) and node_decode.json (node_decode.mjs)."""
import csv, json, os, subprocess, sys

out, prefix = sys.argv[1], sys.argv[2]
S = json.load(open(os.path.join(out, 'sizes.json')))
D = json.load(open(os.path.join(out, 'decode.json'))) if os.path.exists(os.path.join(out, 'decode.json')) else None
N = json.load(open(os.path.join(out, 'node_decode.json'))) if os.path.exists(os.path.join(out, 'node_decode.json')) else None
root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..')
git = lambda *a: subprocess.run(['git', '-C', root, *a], capture_output=True, text=True).stdout.strip()
CF = os.path.join(out, 'commit.txt')
commit = open(CF).read().strip() if os.path.exists(CF) else git('rev-parse', '--short', 'HEAD')
FR = ['0.25', '0.1', '0.05']
FN = {'0.25': '1/4', '0.1': '1/10', '0.05': '1/20'}
NAMES = {'kauai512': 'Kauai SRTM3, 512²', 'kauai256': 'Kauai SRTM3, 256²', 'srtm1_512': 'SRTM1 N45E013 (3600²), 512²'}
LABEL = {'terrarium-png': 'Terrarium PNG', 'terrarium-webp': 'Terrarium WebP (Rust image-webp)',
         'libwebp': 'Terrarium WebP (libwebp -lossless -exact -z 9)', 'mapbox-png': 'Terrain-RGB PNG', 'f32': 'f32 (uncompressed)'}
for f in FR:
    LABEL['vtz-' + f] = f'vtz, bound {FN[f]} pixel'
    LABEL['lerc-' + f] = f'LERC2, maxZErr {FN[f]} pixel'
rows = []
md = [f'# vtz web against raster-dem tile encodings — {os.path.basename(prefix)[4:]}, commit {commit}', '',
      'Made by `benches/web/run.sh` (see benches/README.md, "Web terrain (vtz web)"). Archives: `target/ci/vtz web`, '
      'z0 to the default max zoom; libwebp and LERC archives are bench.py\'s re-encodings of the Terrarium PNG and f32 '
      'tiles with the same tile ids, written with the same header padding and metadata. Tile bytes = the sum over '
      'addressed tiles (what a client downloads); archive = the .pmtiles file (identical tiles stored once).', '']

def mb(b): return f'{b:,}'

import hashlib
W = os.path.join(out, 'vtz.wasm')
if os.path.exists(W):
    wb = open(W, 'rb').read()
    simd = os.path.join(out, 'vtz.wasm.simd')
    simd = open(simd).read().strip() if os.path.exists(simd) else '?'
    md += [f'vtz.wasm (snapshot in OUTDIR): {len(wb):,} bytes, sha256 {hashlib.sha256(wb).hexdigest()[:16]}…, '
           f'{simd} lines of SIMD (v128) instructions in its wasm-dis text.', '']
md += ['## Sizes', '']
for name, s in S['summary'].items():
    u = s['_']
    md += [f'### {NAMES.get(name, name)}: {u["tiles"]} tiles, z0–{u["max_zoom"]}', '',
           '| format | archive bytes | tile bytes |', '|---|---:|---:|']
    for fmt, v in s.items():
        if fmt == '_': continue
        md.append(f'| {LABEL[fmt]} | {mb(v["archive"])} | {mb(v["tiles"])} |')
        rows.append(['size', name, fmt, 'archive_bytes', v['archive']]); rows.append(['size', name, fmt, 'tile_bytes', v['tiles']])
    md += ['', '| vtz at | ÷ WebP libwebp | ÷ WebP Rust | ÷ Terrarium PNG | ÷ Terrain-RGB PNG | ÷ LERC same bound |',
           '|---|---:|---:|---:|---:|---:|']
    for f in FR:
        cells = []
        for other in ['libwebp', 'terrarium-webp', 'terrarium-png', 'mapbox-png', 'lerc-' + f]:
            ra = s['vtz-' + f]['archive'] / s[other]['archive']; rt = s['vtz-' + f]['tiles'] / s[other]['tiles']
            cells.append(f'{ra:.3f} ({rt:.3f})')
            rows.append(['ratio', name, f'vtz-{f}/{other}', 'archive', round(ra, 4)]); rows.append(['ratio', name, f'vtz-{f}/{other}', 'tiles', round(rt, 4)])
        md.append(f'| {FN[f]} | ' + ' | '.join(cells) + ' |')
    md += ['', 'archive ratio (tile-byte ratio). Target: vtz ≤ 0.25× the Terrarium-WebP-lossless archive at 1/10.', '']

md += ['## Per zoom', '']
for name in S['summary']:
    zs = [z for z in S['zooms'] if z['dataset'] == name]
    md += [f'### {NAMES.get(name, name)}: bytes per zoom', '',
           '| z | tiles | bound 1/10 (m) | vtz 1/4 | vtz 1/10 | vtz 1/20 | LERC 1/4 | LERC 1/10 | LERC 1/20 | Terrarium PNG | WebP Rust | WebP libwebp | Terrain-RGB |',
           '|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|']
    for z in zs:
        md.append(f'| {z["zoom"]} | {z["tiles"]} | {z["bound_0.1"]:.3f} | ' + ' | '.join(
            mb(z[k]) for k in ['vtz_0.25', 'vtz_0.1', 'vtz_0.05', 'lerc_0.25', 'lerc_0.1', 'lerc_0.05',
                               'terrarium-png', 'terrarium-webp', 'libwebp', 'mapbox-png']) + ' |')
        for k, v in z.items():
            if k not in ('dataset', 'zoom'): rows.append(['zoom', name, f'z{z["zoom"]}', k, v])
    md += ['', f'### {NAMES.get(name, name)}: max error per zoom, metres (bound / vtz from --json / LERC decoded)', '',
           '| z | 1/4: bound | vtz | LERC | 1/10: bound | vtz | LERC | 1/20: bound | vtz | LERC |', '|---:|' + '---:|' * 9]
    worst = {'vtz': (0.0, None), 'lerc': (0.0, None)}
    for z in zs:
        cells = []
        for f in FR:
            cells += [f'{z["bound_" + f]:.3f}', f'{z["vtz_err_" + f]:.3f}', f'{z["lerc_err_" + f]:.3f}']
            for c in worst:
                q = z[f'{c}_err_{f}'] / z['bound_' + f]
                if q > worst[c][0]: worst[c] = (q, f'z{z["zoom"]} at {FN[f]}: {z[f"{c}_err_{f}"]!r} m against {z["bound_" + f]!r} m')
        md.append(f'| {z["zoom"]} | ' + ' | '.join(cells) + ' |')
    md += ['', 'Largest error ÷ bound over all zooms and fractions: ' + '; '.join(
        f'{c} {q:.6f} ({w})' for c, (q, w) in worst.items()) + '.', '']

if D:
    md += ['## Decode time per tile, headless Chromium', '',
           f'Chromium {D["chromium"]}, main thread unless said, {D["passes"]} timed passes after a warm-up, every format '
           'taking its turn in each pass; medians over passes × tiles, ms. "finest" = the tiles of the finest zoom, "all" = '
           'every tile; [min–max] of the per-pass medians (finest) shows the noise of the shared 2-core machine.', '']
    for name, r in D['datasets'].items():
        md += [f'### {NAMES.get(name, name)}', '', '| format | operation | finest (ms) | all (ms) | pass medians (finest) |', '|---|---|---:|---:|---|']
        for k, v in r['results'].items():
            fmt, op = k.split('/', 1)
            md.append(f'| {LABEL[fmt]} | {op} | {v["finest"]:.2f} | {v["all"]:.2f} | {v["pass_medians_min"]:.2f}–{v["pass_medians_max"]:.2f} |')
            for m in ['finest', 'all', 'pass_medians_min', 'pass_medians_max']:
                rows.append(['chromium_ms', name, fmt, f'{op}:{m}', round(v[m], 4)])
        md.append('')
        r2 = r['results']
        png = r2.get('terrarium-png/bitmap+getImageData', {}).get('finest')
        for f in FR:
            v = r2.get(f'vtz-{f}/decode+rgba')
            if v and png:
                md.append(f'- vtz {FN[f]}: decode+RGBA {v["finest"]:.2f} ms per finest tile: target ≤ 5 ms '
                          f'{"met" if v["finest"] <= 5 else "not met"}; {v["finest"] / png:.2f}× the Terrarium PNG path '
                          f'(createImageBitmap + getImageData, {png:.2f} ms): target ≤ 2× {"met" if v["finest"] <= 2 * png else "not met"}.')
        md.append('')
if N:
    md += ['## Decode time per tile, the same wasm in Node', '', f'Node {N["node"]}, web/src/vtz.js, {N["passes"]} passes after a warm-up, medians, ms.', '',
           '| archive | decode finest | decode all | decode+RGBA finest | decode+RGBA all |', '|---|---:|---:|---:|---:|']
    for k, v in N['results'].items():
        md.append(f'| {k} | {v["decode"]["finest"]:.2f} | {v["decode"]["all"]:.2f} | {v["decode+rgba"]["finest"]:.2f} | {v["decode+rgba"]["all"]:.2f} |')
        for op in v:
            for m in ['finest', 'all']:
                rows.append(['node_ms', k.split('.')[0], k.split('.', 1)[1], f'{op}:{m}', round(v[op][m], 4)])
    md.append('')
NV = os.path.join(out, 'native.json')
nv = json.load(open(NV)) if os.path.exists(NV) else {}
if nv:
    md += ['## Native reference (one thread, in process)', '',
           f'web/wasm\'s `native_bench` example (decode + f32 conversion, `--threads 1`, 8 decodes a tile, median; '
           f'binary {next(iter(nv.values()))["exe"]}), finest-zoom tiles, ms.', '',
           '| archive | finest tiles | median over tiles | fastest tile | slowest tile |', '|---|---:|---:|---:|---:|']
    for k, v in nv.items():
        md.append(f'| {k} | {v["n_finest"]} | {v["finest_median_ms"]:.2f} | {v["finest_min_ms"]:.2f} | {v["finest_max_ms"]:.2f} |')
        rows.append(['native_ms', k.split('.')[0], k.split('.', 1)[1], 'decode:finest', round(v['finest_median_ms'], 4)])
    md.append('')
open(prefix + '.md', 'w').write('\n'.join(md) + '\n')
with open(prefix + '.csv', 'w', newline='') as fh:
    w = csv.writer(fh); w.writerow(['section', 'dataset', 'format', 'metric', 'value']); w.writerows(rows)
