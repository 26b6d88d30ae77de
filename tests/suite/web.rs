//! `vtz web`: raster-dem pyramids in PMTiles, read back by a PMTiles reader written here from
//! the spec (protomaps' `spec/v3/spec.md`), each tile decoded and checked against the source
//! resampled independently, the levels against each other, the RGB formats against the vtz
//! tiles; the CLI's errors.

use crate::common;

use common::*;
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::io::Read;
use vtz::web::{TileFormat, WebRequest};

/// A PMTiles v3 archive as the spec describes it: header fields and every tile by (z, x, y).
struct Archive {
    min_zoom: u8,
    max_zoom: u8,
    tile_type: u8,
    clustered: bool,
    bounds: [f64; 4],
    metadata: serde_json::Value,
    tiles: BTreeMap<(u8, u32, u32), Vec<u8>>,
}

fn varint(b: &[u8], p: &mut usize) -> u64 {
    let mut v = 0u64;
    let mut shift = 0;
    loop {
        let c = b[*p];
        *p += 1;
        v |= u64::from(c & 0x7f) << shift;
        if c & 0x80 == 0 {
            return v;
        }
        shift += 7;
    }
}

fn gunzip(b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(b)
        .read_to_end(&mut out)
        .unwrap();
    out
}

/// (tile id, offset, length, run length) of a directory.
fn directory(b: &[u8]) -> Vec<(u64, u64, u64, u64)> {
    let mut p = 0;
    let n = varint(b, &mut p) as usize;
    assert!(n > 0);
    let mut ids = Vec::with_capacity(n);
    let mut last = 0;
    for _ in 0..n {
        last += varint(b, &mut p);
        ids.push(last);
    }
    let runs: Vec<u64> = (0..n).map(|_| varint(b, &mut p)).collect();
    let lens: Vec<u64> = (0..n).map(|_| varint(b, &mut p)).collect();
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let v = varint(b, &mut p);
        let off = if v == 0 {
            assert!(i > 0, "the first offset is explicit");
            out.last()
                .map(|e: &(u64, u64, u64, u64)| e.1 + e.2)
                .unwrap()
        } else {
            v - 1
        };
        assert!(lens[i] > 0, "zero-length entries are forbidden");
        out.push((ids[i], off, lens[i], runs[i]));
    }
    assert_eq!(p, b.len(), "trailing bytes after the directory");
    out
}

/// (z, x, y) of a tile id: the zoom's first id is (4^z − 1)/3, then the Hilbert index.
fn coord(id: u64) -> (u8, u32, u32) {
    let mut z = 0u8;
    let mut base = 0u64;
    while base + (1u64 << (2 * z)) <= id {
        base += 1u64 << (2 * z);
        z += 1;
    }
    let n = 1u64 << z;
    let mut d = id - base;
    let (mut x, mut y) = (0u64, 0u64);
    let mut s = 1u64;
    while s < n {
        let rx = 1 & (d / 2);
        let ry = 1 & (d ^ rx);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        x += s * rx;
        y += s * ry;
        d /= 4;
        s *= 2;
    }
    (z, x as u32, y as u32)
}

fn read_archive(b: &[u8]) -> Archive {
    assert_eq!(&b[..7], b"PMTiles");
    assert_eq!(b[7], 3);
    let u = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    let i = |o: usize| i32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as f64 / 1e7;
    let (root_off, root_len) = (u(8) as usize, u(16) as usize);
    let (meta_off, meta_len) = (u(24) as usize, u(32) as usize);
    let leaf_off = u(40) as usize;
    let data_off = u(56) as usize;
    assert_eq!(b[97], 2, "internal compression gzip");
    assert_eq!(b[98], 1, "tiles uncompressed");
    assert!(
        root_off + root_len <= 16384,
        "header and root in the first 16 KiB"
    );
    let metadata = serde_json::from_slice(&gunzip(&b[meta_off..meta_off + meta_len])).unwrap();
    let mut tiles = BTreeMap::new();
    let mut dirs = vec![gunzip(&b[root_off..root_off + root_len])];
    let mut addressed = 0u64;
    while let Some(d) = dirs.pop() {
        for (id, off, len, run) in directory(&d) {
            if run == 0 {
                let s = leaf_off + off as usize;
                dirs.push(gunzip(&b[s..s + len as usize]));
                continue;
            }
            let s = data_off + off as usize;
            let bytes = b[s..s + len as usize].to_vec();
            for k in 0..run {
                tiles.insert(coord(id + k), bytes.clone());
            }
            addressed += run;
        }
    }
    assert_eq!(addressed, u(72), "addressed tiles");
    Archive {
        clustered: b[96] == 1,
        tile_type: b[99],
        min_zoom: b[100],
        max_zoom: b[101],
        bounds: [i(102), i(106), i(110), i(114)],
        metadata,
        tiles,
    }
}

fn web(r: &vtz::Raster, req: &WebRequest) -> (Vec<u8>, vtz::web::WebReport) {
    let mut out = std::io::Cursor::new(Vec::new());
    let rep = vtz::web::write_web_to(r, req, &mut out, &|_| {}).unwrap();
    (out.into_inner(), rep)
}

/// Heights of a decoded tile, NaN = nodata.
fn heights(t: &[u8]) -> Vec<f64> {
    let r = vtz::decode(t).unwrap();
    (0..r.len())
        .map(|i| if r.is_valid(i) { r.data[i] } else { f64::NAN })
        .collect()
}

/// The source at longitude/latitude, sampled as the web pyramid promises (bilinear between
/// pixel centres, weights over valid samples), written here from the geotransform alone.
fn expected(r: &vtz::Raster, lon: f64, lat: f64) -> f64 {
    let g = r.georef.as_ref().unwrap();
    let c = if g.raster_type == vtz::RasterType::Area {
        0.5
    } else {
        0.0
    };
    let col = (lon - g.origin[0]) / g.pixel_size[0] - c;
    let row = (g.origin[1] - lat) / g.pixel_size[1] - c;
    let (w, h) = (r.width as f64, r.height as f64);
    if col < -0.5 || row < -0.5 || col > w - 0.5 || row > h - 0.5 {
        return f64::NAN;
    }
    let (col, row) = (col.clamp(0.0, w - 1.0), row.clamp(0.0, h - 1.0));
    let (c0, r0) = (col.floor() as usize, row.floor() as usize);
    let (fx, fy) = (col - c0 as f64, row - r0 as f64);
    let (mut s, mut ws) = (0.0, 0.0);
    for (dx, dy, wt) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let (cc, rr) = ((c0 + dx).min(r.width - 1), (r0 + dy).min(r.height - 1));
        let i = rr * r.width + cc;
        if wt > 0.0 && r.is_valid(i) {
            s += wt * r.data[i];
            ws += wt;
        }
    }
    if ws > 0.0 { s / ws } else { f64::NAN }
}

fn kauai() -> vtz::Raster {
    read_corpus("srtm3_N22W160_kauai.hgt")
}

#[test]
fn vtz_tiles_hold_the_source_resampled_within_each_zooms_bound() {
    let r = kauai();
    let mut req = WebRequest::default();
    req.tile_size = 256;
    req.max_zoom = Some(10);
    req.min_zoom = 6;
    let (bytes, rep) = web(&r, &req);
    let a = read_archive(&bytes);
    assert_eq!((a.min_zoom, a.max_zoom, a.tile_type), (6, 10, 0));
    assert!(a.clustered);
    assert_eq!(a.tiles.len(), rep.tiles());
    assert_eq!(bytes.len() as u64, rep.bytes);
    // Kauai: 22..23 N, 160..159 W (the .hgt's posts, half a pixel beyond).
    let b = a.bounds;
    assert!(
        (b[0] + 160.0).abs() < 0.01 && (b[2] + 159.0).abs() < 0.01,
        "{b:?}"
    );
    assert!(
        (b[1] - 22.0).abs() < 0.01 && (b[3] - 23.0).abs() < 0.01,
        "{b:?}"
    );
    assert_eq!(a.metadata["encoding"], "vtz");
    assert_eq!(a.metadata["tileSize"], 256);
    let levels = a.metadata["vtz"]["max_error"].as_array().unwrap();
    assert_eq!(levels.len(), 5);
    // The default bound: a tenth of the zoom's ground pixel at 23° N.
    for (l, m) in rep.levels.iter().zip(levels) {
        let px =
            2.0 * PI * 6378137.0 * 23f64.to_radians().cos() / (256.0 * 2f64.powi(l.zoom as i32));
        assert!(
            (l.bound / (0.1 * px) - 1.0).abs() < 1e-4,
            "zoom {}: {} vs {}",
            l.zoom,
            l.bound,
            px
        );
        assert!(l.max_error <= l.bound && l.max_error > 0.0);
        assert_eq!(m["bound"].as_f64().unwrap(), l.bound);
    }
    // Finest zoom: every pixel against the source resampled here.
    let z = 10u8;
    let bound = rep.levels.last().unwrap().bound;
    let (mut checked, mut nodata) = (0, 0);
    for (&(tz, x, y), t) in a.tiles.range((z, 0, 0)..=(z, u32::MAX, u32::MAX)) {
        assert_eq!(tz, z);
        let h = heights(t);
        assert_eq!(h.len(), 256 * 256);
        for (k, &v) in h.iter().enumerate() {
            let (i, j) = (k % 256, k / 256);
            let n = 2f64.powi(z as i32) * 256.0;
            let mx = (f64::from(x) * 256.0 + i as f64 + 0.5) / n;
            let my = (f64::from(y) * 256.0 + j as f64 + 0.5) / n;
            let lon = mx * 360.0 - 180.0;
            let lat = (PI * (1.0 - 2.0 * my)).sinh().atan().to_degrees();
            let e = expected(&r, lon, lat);
            if e.is_nan() {
                assert!(
                    v.is_nan(),
                    "{z}/{x}/{y} pixel {i},{j}: {v} outside the source"
                );
                nodata += 1;
            } else {
                // The level holds float32 heights: their rounding on top of the bound.
                assert!(
                    (v - e).abs() <= bound + 1e-3,
                    "{z}/{x}/{y} {i},{j}: {v} vs {e}"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 500_000 && nodata > 10_000, "{checked} {nodata}");
    // Each coarser pixel is the mean of its four children, within both bounds.
    for zc in 6..10u8 {
        let (bp, bc) = (
            rep.levels[(zc - 6) as usize].bound,
            rep.levels[(zc - 5) as usize].bound,
        );
        for (&(_, x, y), t) in a.tiles.range((zc, 0, 0)..=(zc, u32::MAX, u32::MAX)) {
            let p = heights(t);
            let kids: Vec<Option<Vec<f64>>> = (0..4)
                .map(|k| {
                    a.tiles
                        .get(&(zc + 1, 2 * x + k % 2, 2 * y + k / 2))
                        .map(|t| heights(t))
                })
                .collect();
            for j in 0..256usize {
                for i in 0..256usize {
                    let (ci, cj) = (2 * i % 256, 2 * j % 256);
                    let Some(kid) = &kids[(i / 128) + 2 * (j / 128)] else {
                        continue;
                    };
                    let c = [
                        kid[cj * 256 + ci],
                        kid[cj * 256 + ci + 1],
                        kid[(cj + 1) * 256 + ci],
                        kid[(cj + 1) * 256 + ci + 1],
                    ];
                    let v = p[j * 256 + i];
                    if c.iter().all(|v| v.is_nan()) {
                        assert!(v.is_nan());
                    } else if c.iter().all(|v| !v.is_nan()) {
                        let mean = c.iter().sum::<f64>() / 4.0;
                        assert!((v - mean).abs() <= bp + bc + 1e-3, "{zc}/{x}/{y} {i},{j}");
                    }
                }
            }
        }
    }
}

#[test]
fn rgb_formats_hold_the_same_pyramid() {
    let r = kauai();
    let mut req = WebRequest::default();
    req.max_zoom = Some(9);
    req.min_zoom = 8;
    let (vb, vrep) = web(&r, &req);
    let v = read_archive(&vb);
    // The uncompressed float32 pyramid: what the vtz tiles hold within their bound.
    req.format = TileFormat::F32;
    let f = read_archive(&web(&r, &req).0);
    assert_eq!(
        f.tiles.keys().collect::<Vec<_>>(),
        v.tiles.keys().collect::<Vec<_>>()
    );
    for (key, t) in &f.tiles {
        let bound = vrep.levels[(key.0 - 8) as usize].bound;
        let vt = heights(&v.tiles[key]);
        assert_eq!(t.len(), 512 * 512 * 4);
        for (k, c) in t.chunks_exact(4).enumerate() {
            let h = f64::from(f32::from_le_bytes(c.try_into().unwrap()));
            assert_eq!(h.is_nan(), vt[k].is_nan());
            assert!(h.is_nan() || (h - vt[k]).abs() <= bound, "{key:?} {k}");
        }
    }
    for (format, tile_type, step, base) in [
        (TileFormat::TerrariumPng, 2u8, 1.0 / 256.0, -32768.0),
        (TileFormat::TerrariumWebp, 4, 1.0 / 256.0, -32768.0),
        (TileFormat::MapboxPng, 2, 0.1, -10000.0),
    ] {
        req.format = format;
        let (b, rep) = web(&r, &req);
        let a = read_archive(&b);
        assert_eq!(a.tile_type, tile_type, "{format:?}");
        assert_eq!(
            a.tiles.keys().collect::<Vec<_>>(),
            v.tiles.keys().collect::<Vec<_>>()
        );
        let enc = a.metadata["encoding"].as_str().unwrap();
        assert_eq!(enc, if step == 0.1 { "mapbox" } else { "terrarium" });
        for (key, img) in &a.tiles {
            let rgb = image::load_from_memory(img).unwrap().to_rgb8();
            assert_eq!(rgb.dimensions(), (512, 512));
            let vt = heights(&v.tiles[key]);
            let bound = vrep.levels[(key.0 - 8) as usize].bound;
            for (k, p) in rgb.pixels().enumerate() {
                let code = (u32::from(p[0]) << 16) | (u32::from(p[1]) << 8) | u32::from(p[2]);
                let h = base + f64::from(code) * step;
                if vt[k].is_nan() {
                    assert_eq!(h, 0.0, "nodata is written as 0 m");
                } else {
                    assert!(
                        (h - vt[k]).abs() <= bound + step / 2.0 + 1e-3,
                        "{key:?} {k}"
                    );
                }
            }
        }
        // The vtz archive is several times smaller than every lossless RGB one.
        assert!(
            b.len() > 3 * vb.len(),
            "{format:?}: {} vs {}",
            b.len(),
            vb.len()
        );
        assert!(rep.levels.iter().all(|l| l.max_error <= step / 2.0 + 1e-9));
    }
}

#[test]
fn projected_sources_are_reprojected() {
    // Big Tujunga, UTM 11N (EPSG:32611), about 118.15 W 34.32 N.
    let Some(r) = read_shared("srtm30m_bigtujunga_utm11.tif") else {
        return;
    };
    let mut req = WebRequest::default();
    req.max_zoom = Some(11);
    req.min_zoom = 11;
    let (b, rep) = web(&r, &req);
    let a = read_archive(&b);
    let bb = a.bounds;
    assert!(
        (bb[0] + 118.35).abs() < 0.01 && (bb[2] + 117.95).abs() < 0.01,
        "{bb:?}"
    );
    assert!(
        (bb[1] - 34.23).abs() < 0.01 && (bb[3] - 34.41).abs() < 0.01,
        "{bb:?}"
    );
    // The summit of the source (Mount Lukens ridge, 2295 m max) survives resampling: the
    // tiles' largest height is near it, never above it by more than the bound.
    let top = a
        .tiles
        .values()
        .flat_map(|t| heights(t))
        .filter(|v| !v.is_nan())
        .fold(f64::MIN, f64::max);
    let bound = rep.levels[0].bound;
    assert!(top <= 2295.0 + bound && top > 2200.0, "{top}");
}

#[test]
fn archives_are_the_same_bytes_on_any_thread_count() {
    let r = kauai();
    let mut req = WebRequest::default();
    req.max_zoom = Some(9);
    let one = vtz::on_threads(1, || web(&r, &req).0).unwrap();
    let two = vtz::on_threads(2, || web(&r, &req).0).unwrap();
    assert!(one == two);
}

#[test]
fn rasters_that_cannot_be_placed_and_bad_requests_are_refused() {
    let mut r = kauai();
    r.georef = None;
    let mut out = std::io::Cursor::new(Vec::new());
    let e = vtz::web::write_web_to(&r, &WebRequest::default(), &mut out, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("no georeferencing"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("k.pmtiles");
    let k = corpus("srtm3_N22W160_kauai.hgt");
    for (args, msg) in [
        (vec!["--tile-size", "300"], "--tile-size must be 256 or 512"),
        (vec!["--format", "jpeg"], "--format must be one of"),
        (vec!["--pixel-fraction", "0"], "--pixel-fraction must be"),
        (vec!["--max-zoom", "25"], "--max-zoom must be at most 24"),
        (
            vec!["--min-zoom", "9", "--max-zoom", "8"],
            "--min-zoom 9 is above",
        ),
        (vec!["--effort", "0"], "--effort must be in 1..=9"),
    ] {
        let mut a = vec!["web", &k, "-o", out.to_str().unwrap()];
        a.extend(args);
        let o = vtz(&a);
        assert_eq!(o.status.code(), Some(2), "{a:?}");
        assert!(stderr(&o).contains(msg), "{a:?}: {}", stderr(&o));
        assert!(!out.exists());
    }
    let o = vtz([
        "web",
        &corpus("scape_crater.png"),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no georeferencing"), "{}", stderr(&o));
    let o = vtz([
        "web",
        &k,
        "-o",
        out.to_str().unwrap(),
        "--max-zoom",
        "8",
        "-q",
        "--json",
    ]);
    let j = json(&o);
    assert_eq!(j["levels"].as_array().unwrap().len(), 9);
    assert_eq!(
        j["bytes"].as_u64().unwrap(),
        std::fs::metadata(&out).unwrap().len()
    );
    let o = vtz(["web", &k, "-o", out.to_str().unwrap(), "--max-zoom", "8"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("exists (use --force"), "{}", stderr(&o));
}
