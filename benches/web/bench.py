"""benches/web/bench.py OUTDIR NAME [NAME...] : sizes of `vtz web` archives made by run.sh,
plus libwebp lossless (cwebp -lossless -exact -z 9 of every Terrarium PNG tile) and LERC2
(pylerc, maxZErr = vtz's per-zoom bound at each pixel fraction, NaN masked) of the f32
pyramid, written as PMTiles archives with the same tile ids (for decode.mjs). LERC's max
error is measured by decoding. Writes OUTDIR/sizes.csv, OUTDIR/zooms.csv, OUTDIR/sizes.json."""
import csv, json, os, subprocess, sys, tempfile
import numpy as np
import lerc
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import pmt

FRACS = ['0.25', '0.1', '0.05']
out, names = sys.argv[1], sys.argv[2:]
rows, zrows, summary = [], [], {}


def tile_sum(tiles):
    return sum(len(b) for b in tiles.values())


for name in names:
    base = os.path.join(out, name)
    arch = {}
    for fmt in ['terrarium-png', 'terrarium-webp', 'mapbox-png', 'f32'] + ['vtz-' + f for f in FRACS]:
        h, t, size = pmt.read(f'{base}.{fmt}.pmtiles')
        arch[fmt] = dict(h=h, tiles=t, size=size, json=json.load(open(f'{base}.{fmt}.json')))
    ts = arch['f32']['json']['tile_size']
    ids = sorted(arch['f32']['tiles'])
    for fmt, a in arch.items():
        assert sorted(a['tiles']) == ids, (name, fmt)
    # libwebp lossless of the Terrarium PNG tiles (each distinct PNG once)
    webp, cache = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for tid in ids:
            png = arch['terrarium-png']['tiles'][tid]
            if png not in cache:
                open(f'{tmp}/t.png', 'wb').write(png)
                subprocess.run(['cwebp', '-quiet', '-lossless', '-exact', '-z', '9', f'{tmp}/t.png',
                                '-o', f'{tmp}/t.webp'], check=True)
                cache[png] = open(f'{tmp}/t.webp', 'rb').read()
            webp[tid] = cache[png]
    size = pmt.write(f'{base}.libwebp.pmtiles', webp, arch['terrarium-png']['h'], 4)
    arch['libwebp'] = dict(tiles=webp, size=size)
    # LERC2 of the f32 tiles at each fraction's per-zoom bound
    lerr = {}
    for f in FRACS:
        bound = {l['zoom']: l['bound'] for l in arch['vtz-' + f]['json']['levels']}
        lt, err, cache = {}, {}, {}
        for tid in ids:
            raw = arch['f32']['tiles'][tid]
            z = pmt.zoom_of(tid)
            if raw not in cache:
                a = np.frombuffer(raw, '<f4').reshape(ts, ts)
                valid = ~np.isnan(a)
                has_mask = not valid.all()
                r, n, blob = lerc.encode(np.where(valid, a, 0).astype(np.float32), 1, has_mask,
                                         valid.astype(np.uint8) if has_mask else None, bound[z], 1)
                assert r == 0, r
                blob = bytes(blob[:n])
                r, d, m = lerc.decode(blob)[:3]
                assert r == 0
                dv = valid if m is None else m.astype(bool)
                assert (dv == valid).all(), 'LERC mask'
                e = float(np.abs(d.astype(np.float64) - a)[valid].max()) if valid.any() else 0.0
                cache[raw] = (blob, e)
            lt[tid], e = cache[raw]
            err[z] = max(err.get(z, 0.0), e)
        size = pmt.write(f'{base}.lerc-{f}.pmtiles', lt, arch['f32']['h'], 0)
        arch['lerc-' + f] = dict(tiles=lt, size=size)
        lerr[f] = err
    fmts = ['vtz-' + f for f in FRACS] + ['terrarium-png', 'terrarium-webp', 'libwebp', 'mapbox-png'] + \
        ['lerc-' + f for f in FRACS] + ['f32']
    s = {fmt: dict(archive=arch[fmt]['size'], tiles=tile_sum(arch[fmt]['tiles'])) for fmt in fmts}
    s['_'] = dict(tile_size=ts, tiles=len(ids), max_zoom=max(map(pmt.zoom_of, ids)))
    summary[name] = s
    for fmt in fmts:
        rows.append(dict(dataset=name, format=fmt, tile_size=ts, tiles=len(ids),
                         archive_bytes=s[fmt]['archive'], tile_bytes=s[fmt]['tiles']))
    zooms = sorted(set(map(pmt.zoom_of, ids)))
    for z in zooms:
        zid = [i for i in ids if pmt.zoom_of(i) == z]
        r = dict(dataset=name, zoom=z, tiles=len(zid))
        for f in FRACS:
            lv = next(l for l in arch['vtz-' + f]['json']['levels'] if l['zoom'] == z)
            r[f'bound_{f}'] = lv['bound']
            r[f'vtz_{f}'] = sum(len(arch['vtz-' + f]['tiles'][i]) for i in zid)
            r[f'vtz_err_{f}'] = lv['max_error']
            r[f'lerc_{f}'] = sum(len(arch['lerc-' + f]['tiles'][i]) for i in zid)
            r[f'lerc_err_{f}'] = lerr[f][z]
        for fmt in ['terrarium-png', 'terrarium-webp', 'libwebp', 'mapbox-png']:
            r[fmt] = sum(len(arch[fmt]['tiles'][i]) for i in zid)
        zrows.append(r)
    print(name, json.dumps(s), file=sys.stderr)

for fname, rs in [('sizes.csv', rows), ('zooms.csv', zrows)]:
    with open(os.path.join(out, fname), 'w', newline='') as fh:
        w = csv.DictWriter(fh, fieldnames=list(rs[0]))
        w.writeheader(); w.writerows(rs)
json.dump(dict(summary=summary, zooms=zrows), open(os.path.join(out, 'sizes.json'), 'w'), indent=1)
