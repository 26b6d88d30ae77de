//! `--scale` as GIS users expect it (issue 25, items 16–18): every method decodes at any
//! scale; the output is laid out as `gdal_translate -outsize` lays it out (⌊w·s⌋ × ⌊h·s⌋
//! over the source's extent, pixel is area); the scale is parsed exactly by one parser.

use crate::common;

use common::{Kind, bits, decode_opts, encode_opts, stderr, terrain, tmp, vtz};
use vtz::{ErrorBound, Method, Raster, RasterType, SampleType, Scale};

const METHODS: [Method; 5] = [
    Method::RESIDUAL,
    Method::GRID,
    Method::HAAR,
    Method::FIS,
    Method::SIBSON,
];

fn georeferenced(mut r: Raster) -> Raster {
    r.georef = Some(vtz::Georef {
        origin: [1000.0, 2000.0],
        pixel_size: [10.0, 10.0],
        raster_type: RasterType::Area,
        epsg: Some(32633),
        wkt: None,
        geokeys: None,
    });
    r
}

fn at_scale(bytes: &[u8], s: Scale, threads: usize) -> Raster {
    vtz::decode_with(
        bytes,
        &decode_opts(|o| {
            o.scale = Some(s);
            o.threads = threads;
        }),
    )
    .unwrap_or_else(|e| panic!("scale {s:?}: {e}"))
}

/// The source sample nearest output index i: round((i + ½)/s − ½), halves up, in the axis.
fn nearest(i: usize, n: usize, s: Scale) -> usize {
    (((2 * i as u64 + 1) * s.den as u64) / (2 * s.num as u64)).min(n as u64 - 1) as usize
}

/// The two source samples around output index i (clamped): ⌊x⌋ and ⌊x⌋ + 1 for
/// x = (i + ½)/s − ½.
fn around(i: usize, n: usize, s: Scale) -> [usize; 2] {
    let p = (2 * i as i64 + 1) * s.den as i64 - s.num as i64;
    let x0 = p.div_euclid(2 * s.num as i64);
    let c = |x: i64| x.clamp(0, n as i64 - 1) as usize;
    [c(x0), c(x0 + 1)]
}

/// Every method, at scales up and down, whole and fractional: GDAL's size and
/// geotransform, validity from the nearest source sample, values within the decoded (and so
/// within the bound of the source's) samples around each point, the source samples
/// themselves where an output centre falls on one, and the same bits for any thread count.
#[test]
fn every_method_decodes_at_any_scale_in_gdals_layout() {
    let (w, h) = (60, 44);
    let bound = 10.0;
    for st in [SampleType::F32, SampleType::I16] {
        let src = georeferenced(terrain(Kind::Fbm, w, h, 11, true, st));
        for m in METHODS {
            let opts = encode_opts(&[m], Some(ErrorBound::Abs(bound)));
            let bytes = vtz::encode(&src, &opts).unwrap();
            let base = vtz::decode(&bytes).unwrap();
            let what = |s: &str| format!("{} {:?} at {s}", m.name(), st);
            for s in ["2", "0.5", "3/2", "3", "1/3", "2/5"] {
                let sc = Scale::parse(s).unwrap();
                let out = at_scale(&bytes, sc, 1);
                let (num, den) = (sc.num as usize, sc.den as usize);
                // ⌊w·s⌋ × ⌊h·s⌋, as gdal_translate -outsize truncates.
                assert_eq!(
                    (out.width, out.height),
                    (w * num / den, h * num / den),
                    "{}",
                    what(s)
                );
                assert_eq!(out.sample_type, st);
                // The same corner, pixel size / s.
                let g = out.georef.as_ref().unwrap();
                assert_eq!(g.origin, [1000.0, 2000.0], "{}", what(s));
                let px = 10.0 * den as f64 / num as f64;
                assert_eq!(g.pixel_size, [px, px], "{}", what(s));
                assert_eq!(g.raster_type, RasterType::Area);
                let (ow, oh) = (out.width, out.height);
                for j in 0..oh {
                    for i in 0..ow {
                        let o = j * ow + i;
                        let near = nearest(j, h, sc) * w + nearest(i, w, sc);
                        if m == Method::SIBSON {
                            // Sites: also nodata outside the sites' hull.
                            assert!(!out.is_valid(o) || base.is_valid(near), "{}", what(s));
                        } else {
                            assert_eq!(
                                out.is_valid(o),
                                base.is_valid(near),
                                "{} ({i},{j})",
                                what(s)
                            );
                        }
                        if !out.is_valid(o) {
                            assert_eq!(out.data[o], common::NODATA, "{}", what(s));
                            continue;
                        }
                        let v = out.data[o];
                        // Where the centre falls on a source sample, that sample's value.
                        let p = (2 * i + 1) * den;
                        let q = (2 * j + 1) * den;
                        if p % (2 * num) == num && q % (2 * num) == num {
                            let d = (v - base.data[near]).abs();
                            let tol = if m == Method::SIBSON { 1.0 } else { 0.0 };
                            assert!(
                                d <= tol,
                                "{} ({i},{j}): {v} vs {}",
                                what(s),
                                base.data[near]
                            );
                        }
                        if m == Method::SIBSON {
                            continue;
                        }
                        // Interpolated: within the valid decoded samples around the point,
                        // so within the bound of the source's.
                        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                        let (mut slo, mut shi) = (f64::INFINITY, f64::NEG_INFINITY);
                        for y in around(j, h, sc) {
                            for x in around(i, w, sc) {
                                if base.is_valid(y * w + x) {
                                    lo = lo.min(base.data[y * w + x]);
                                    hi = hi.max(base.data[y * w + x]);
                                    slo = slo.min(src.data[y * w + x]);
                                    shi = shi.max(src.data[y * w + x]);
                                }
                            }
                        }
                        assert!(
                            (lo..=hi).contains(&v),
                            "{} ({i},{j}): {v} outside {lo}..{hi}",
                            what(s)
                        );
                        assert!(v >= slo - bound && v <= shi + bound, "{}", what(s));
                    }
                }
                // Bit-identical on any number of threads.
                assert_eq!(bits(&at_scale(&bytes, sc, 3)), bits(&out), "{}", what(s));
            }
            // Scale 1, however written, is the plain decode.
            for one in [Scale { num: 1, den: 1 }, Scale { num: 2, den: 2 }] {
                let r = at_scale(&bytes, one, 0);
                assert_eq!(bits(&r), bits(&base), "{}", what("1"));
                assert_eq!(r.mask, base.mask);
                assert_eq!(r.georef, base.georef);
            }
        }
    }
}

/// The default method (`best`, which picks the residual layer here) decodes at a scale: the
/// capability files made with default options had lost.
#[test]
fn a_file_made_with_default_options_decodes_at_scale() {
    let src = georeferenced(terrain(Kind::Fbm, 64, 48, 3, false, SampleType::I16));
    let bytes = vtz::encode(&src, &encode_opts(&[], Some(ErrorBound::Abs(1.0)))).unwrap();
    let up = at_scale(&bytes, Scale::parse("2").unwrap(), 0);
    assert_eq!((up.width, up.height), (128, 96));
    let down = at_scale(&bytes, Scale::parse("0.5").unwrap(), 0);
    assert_eq!((down.width, down.height), (32, 24));
}

/// Flat regions are exact at every scale: each output sample whose nearest source sample is
/// in one takes its value, whatever the method interpolates around it.
#[test]
fn flat_regions_are_exact_at_scale() {
    // A lake of 72² samples in whole 8 × 8 blocks: flat regions need 4096 samples and are
    // kept block by block (flat coding 1).
    let (w, h) = (120, 104);
    let mut src = terrain(Kind::Hill, w, h, 5, false, SampleType::F32);
    let lake = |x: usize, y: usize| (24..96).contains(&x) && (16..88).contains(&y);
    for y in 0..h {
        for x in 0..w {
            if lake(x, y) {
                src.data[y * w + x] = 123.25;
            }
        }
    }
    for m in [Method::RESIDUAL, Method::GRID, Method::SIBSON] {
        let bytes = vtz::encode(&src, &encode_opts(&[m], Some(ErrorBound::Abs(2.0)))).unwrap();
        let info = vtz::info(&bytes, Default::default()).unwrap();
        assert!(
            info.sections.iter().any(|s| s.name == "flat"),
            "{}: the lake is a flat region",
            m.name()
        );
        for s in ["2", "3/2", "0.5", "2/3"] {
            let sc = Scale::parse(s).unwrap();
            let out = at_scale(&bytes, sc, 0);
            let mut n = 0;
            for j in 0..out.height {
                for i in 0..out.width {
                    let (x, y) = (nearest(i, w, sc), nearest(j, h, sc));
                    // Inside the lake by one sample: the encoder may leave its rim out.
                    if lake(x.saturating_sub(1), y.saturating_sub(1)) && lake(x + 1, y + 1) {
                        let o = j * out.width + i;
                        assert!(out.is_valid(o));
                        assert_eq!(out.data[o], 123.25, "{} at {s}: ({i},{j})", m.name());
                        n += 1;
                    }
                }
            }
            assert!(n > 100, "{n}");
        }
    }
}

#[test]
fn the_scale_is_parsed_exactly() {
    let f = |s: &str| Scale::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
    for (s, num, den) in [
        ("2", 2, 1),
        ("0.5", 1, 2),
        (".5", 1, 2),
        ("5.", 5, 1),
        ("2.50", 5, 2),
        ("3/2", 3, 2),
        ("6/4", 3, 2),
        ("0.001", 1, 1000),
        ("1e-3", 1, 1000),
        ("2.5E2", 250, 1),
        ("10000", 10000, 1),
        ("0.1", 1, 10),
        (" 007 ", 7, 1),
        ("4294967295", u32::MAX, 1),
        ("1/4294967295", 1, u32::MAX),
    ] {
        assert_eq!(f(s), Scale { num, den }, "{s}");
    }
    for s in [
        "0", "0.0", "0/5", "5/0", "-1", "x", "", "1/-2", "inf", "NaN", "1e", "1/2/3",
    ] {
        let e = Scale::parse(s).expect_err(s).to_string();
        assert!(
            e.contains("is not a positive number or fraction"),
            "{s}: {e}"
        );
    }
    // No silent rounding: what has no exact 32-bit fraction is refused with the range.
    for s in [
        "0.3333333333333333",
        "1e12",
        "1e-10",
        "4294967296",
        "1/4294967296",
    ] {
        let e = Scale::parse(s).expect_err(s).to_string();
        assert!(
            e.contains("not representable exactly") && e.contains("4294967295"),
            "{s}: {e}"
        );
    }
}

/// One parser and one limit: a scale too large for the limits is a limit error whatever its
/// size (10000 was "not a positive number" where 1000 was the limit), one too small for a
/// single sample a usage error, 0.001 is 1/1000 (it was 1/64).
#[test]
fn cli_scales_large_and_small() {
    let d = tempfile::tempdir().unwrap();
    let f = tmp(&d, "t.vtz");
    let src = terrain(Kind::Fbm, 3000, 20, 2, false, SampleType::I16);
    std::fs::write(
        &f,
        vtz::encode(
            &src,
            &encode_opts(&[Method::GRID], Some(ErrorBound::Abs(1.0))),
        )
        .unwrap(),
    )
    .unwrap();
    let out = tmp(&d, "o.asc");
    for s in ["1000", "10000", "1e6"] {
        let o = vtz(["decode", &f, "-o", &out, "--scale", s]);
        assert_eq!(o.status.code(), Some(1), "{s}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(
            e.starts_with("vtz: limit exceeded: ") && e.contains("over the limit"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
        assert!(!std::path::Path::new(&out).exists());
    }
    let o = vtz(["decode", &f, "-o", &out, "--scale", "0.001"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("makes a 3x0 raster"), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("smallest scale for it is 1/20"),
        "{}",
        stderr(&o)
    );
    let o = vtz(["decode", &f, "-o", &out, "--scale", "0.05"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r = vtz::read_path(std::path::Path::new(&out), &Default::default()).unwrap();
    assert_eq!((r.width, r.height), (150, 1));
    let o = vtz([
        "decode",
        &f,
        "-o",
        &out,
        "-f",
        "--scale",
        "0.3333333333333333",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("not representable exactly"),
        "{}",
        stderr(&o)
    );
}

/// A pixel-is-point raster (an SRTM tile) keeps its type: its extent as GDAL sees it (the
/// area pixels around the points) is kept, and the first sample's centre moves to the new
/// first pixel's centre.
#[test]
fn a_pixel_is_point_raster_keeps_its_extent() {
    let mut src = terrain(Kind::Fbm, 41, 41, 9, false, SampleType::I16);
    let px = 1.0 / 1200.0;
    src.georef = Some(vtz::Georef {
        origin: [-160.0, 23.0],
        pixel_size: [px, px],
        raster_type: RasterType::Point,
        epsg: Some(4326),
        wkt: None,
        geokeys: None,
    });
    let bytes = vtz::encode(&src, &encode_opts(&[], Some(ErrorBound::Abs(1.0)))).unwrap();
    let up = at_scale(&bytes, Scale::parse("2").unwrap(), 0);
    assert_eq!((up.width, up.height), (82, 82));
    let g = up.georef.unwrap();
    assert_eq!(g.raster_type, RasterType::Point);
    assert_eq!(g.pixel_size, [px / 2.0, px / 2.0]);
    // The corner (centre − half a pixel) is the source's.
    let tol = 1e-12;
    assert!(
        (g.origin[0] - px / 4.0 - (-160.0 - px / 2.0)).abs() < tol,
        "{:?}",
        g.origin
    );
    assert!(
        (g.origin[1] + px / 4.0 - (23.0 + px / 2.0)).abs() < tol,
        "{:?}",
        g.origin
    );
}

// ---------------------------------------------------------------- overviews

fn overview(
    bytes: &[u8],
    k: u32,
    window: Option<vtz::Window>,
    threads: usize,
) -> vtz::Result<Raster> {
    vtz::decode_with(
        bytes,
        &decode_opts(|o| {
            o.overview = Some(k);
            o.window = window;
            o.threads = threads;
        }),
    )
}

/// Every 2^k-th sample of every 2^k-th row.
fn decimated(r: &Raster, k: u32) -> (usize, usize, Vec<u64>, Vec<bool>) {
    let s = 1 << k;
    let (ow, oh) = (r.width.div_ceil(s), r.height.div_ceil(s));
    let mut v = Vec::new();
    let mut m = Vec::new();
    for y in (0..r.height).step_by(s) {
        for x in (0..r.width).step_by(s) {
            v.push(r.data[y * r.width + x].to_bits());
            m.push(r.is_valid(y * r.width + x));
        }
    }
    (ow, oh, v, m)
}

/// An untiled file's overview K is its full decode at every 2^K-th row and column, bit for
/// bit, for every method and for the residual layer's three codings (range-coded
/// interpolation at the default effort, the fast coding at effort 1, the weighted scan
/// predictor that effort 3 may pick), with nodata holes and flat regions; pixels 2^K times
/// larger from the same corner; a window of it is its crop.
#[test]
fn an_untiled_overview_is_the_full_decode_at_every_2k_th_sample() {
    let (w, h) = (75, 53);
    for (kind, st) in [
        (Kind::Fbm, SampleType::F32),
        (Kind::Plateau, SampleType::I16),
    ] {
        let src = georeferenced(terrain(kind, w, h, 5, true, st));
        let mut runs: Vec<(String, vtz::EncodeOptions)> = METHODS
            .iter()
            .map(|&m| {
                (
                    m.name().to_string(),
                    encode_opts(&[m], Some(ErrorBound::Abs(10.0))),
                )
            })
            .collect();
        for effort in [1u8, 3, 5] {
            for bound in [None, Some(ErrorBound::Abs(0.5))] {
                let mut o = encode_opts(&[Method::RESIDUAL], bound);
                o.effort = Some(effort);
                runs.push((format!("residual effort {effort} {bound:?}"), o));
            }
        }
        for (name, opts) in runs {
            let bytes = match vtz::encode(&src, &opts) {
                Ok(b) => b,
                // FIS cannot reach a bound across the plateau's cliff: nothing to decode.
                Err(vtz::Error::Unmet { .. }) if name == "fis" && kind == Kind::Plateau => continue,
                Err(e) => panic!("{name} {kind:?}: {e}"),
            };
            let full = vtz::decode(&bytes).unwrap();
            for k in [1u32, 2, 3, 7] {
                let what = format!("{name} {kind:?} overview {k}");
                let o = overview(&bytes, k, None, 0).unwrap_or_else(|e| panic!("{what}: {e}"));
                let (ow, oh, v, m) = decimated(&full, k);
                assert_eq!((o.width, o.height), (ow, oh), "{what}");
                assert_eq!(bits(&o), v, "{what}");
                let valid: Vec<bool> = (0..o.data.len()).map(|i| o.is_valid(i)).collect();
                assert_eq!(valid, m, "{what}");
                let g = o.georef.as_ref().unwrap();
                assert_eq!(g.origin, [1000.0, 2000.0], "{what}");
                let px = 10.0 * (1u32 << k) as f64;
                assert_eq!(g.pixel_size, [px, px], "{what}");
                if ow > 2 && oh > 2 {
                    let win = vtz::Window {
                        x: 1,
                        y: 1,
                        width: ow - 2,
                        height: oh - 1,
                    };
                    let part = overview(&bytes, k, Some(win), 1).unwrap();
                    let crop: Vec<u64> = (1..oh)
                        .flat_map(|y| (1..ow - 1).map(move |x| (x, y)))
                        .map(|(x, y)| o.data[y * ow + x].to_bits())
                        .collect();
                    assert_eq!(bits(&part), crop, "{what} window");
                    assert_eq!(part.georef.unwrap().origin, [1000.0 + px, 2000.0 - px]);
                }
            }
        }
    }
}

/// A tiled file's overview sample (x, y) is the decode of the tile whose core holds
/// (x·2^K, y·2^K), at the nearest point of that tile's own 2^K lattice (ties to the lower):
/// within the bound of the source there (the source itself when lossless). The same bits
/// for any thread count; a window is the crop of the whole overview.
#[test]
fn a_tiled_overview_takes_each_sample_from_its_tile_within_the_bound() {
    let (w, h) = (301, 233);
    let src = georeferenced(terrain(Kind::Fbm, w, h, 9, true, SampleType::F32));
    for (bound, effort) in [(None, 5u8), (Some(1.5), 5), (Some(1.5), 1)] {
        let mut opts = encode_opts(&[], bound.map(ErrorBound::Abs));
        opts.tile = Some(96);
        opts.effort = Some(effort);
        let bytes = vtz::encode(&src, &opts).unwrap();
        let info = vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec()))
            .unwrap()
            .info()
            .clone();
        let t = info.tiles.as_ref().expect("a tiled file");
        let (tw, th, margin) = (
            t.tile_width as usize,
            t.tile_height as usize,
            t.margin as usize,
        );
        for k in [1u32, 2, 3, 4] {
            let what = format!("{bound:?} effort {effort} overview {k}");
            let s = 1usize << k;
            let o = overview(&bytes, k, None, 1).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(
                (o.width, o.height),
                (w.div_ceil(s), h.div_ceil(s)),
                "{what}"
            );
            // The position a sample comes from, along one axis of n samples.
            let from = |p: usize, t: usize, n: usize| {
                let c = p / t;
                let e0 = (c * t).saturating_sub(margin);
                let e1 = ((c + 1) * t + margin).min(n);
                let m = ((p - e0 + (s - 1) / 2) / s).min((e1 - e0).div_ceil(s) - 1);
                e0 + m * s
            };
            for y in 0..o.height {
                let sy = from(y * s, th, h);
                for x in 0..o.width {
                    let sx = from(x * s, tw, w);
                    let (i, j) = (y * o.width + x, sy * w + sx);
                    assert_eq!(o.is_valid(i), src.is_valid(j), "{what} ({x},{y})");
                    if o.is_valid(i) {
                        let d = (o.data[i] - src.data[j]).abs();
                        assert!(
                            d <= bound.unwrap_or(0.0),
                            "{what} ({x},{y}) from ({sx},{sy}): {d}"
                        );
                    }
                }
            }
            let o2 = overview(&bytes, k, None, 2).unwrap();
            assert_eq!(bits(&o), bits(&o2), "{what}: threads");
            let win = vtz::Window {
                x: 3,
                y: 2,
                width: o.width - 5,
                height: o.height - 3,
            };
            let part = overview(&bytes, k, Some(win), 0).unwrap();
            let crop: Vec<u64> = (2..2 + win.height)
                .flat_map(|y| (3..3 + win.width).map(move |x| (x, y)))
                .map(|(x, y)| o.data[y * o.width + x].to_bits())
                .collect();
            assert_eq!(bits(&part), crop, "{what} window");
        }
    }
}

/// Overview requests that cannot be: a clear error each (library and CLI, exit 2).
#[test]
fn overview_requests_out_of_range_are_errors() {
    let src = terrain(Kind::Fbm, 40, 30, 3, false, SampleType::F32);
    let bytes = vtz::encode(&src, &encode_opts(&[], Some(ErrorBound::Abs(1.0)))).unwrap();
    for k in [0u32, 31] {
        let e = overview(&bytes, k, None, 0).unwrap_err().to_string();
        assert!(e.contains("not in 1..=30"), "{e}");
    }
    let e = overview(
        &bytes,
        1,
        Some(vtz::Window {
            x: 0,
            y: 0,
            width: 21,
            height: 1,
        }),
        0,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("not inside overview 1 (20x15"), "{e}");
    let e = vtz::decode_with(
        &bytes,
        &decode_opts(|o| {
            o.overview = Some(1);
            o.scale = Some(Scale::parse("0.5").unwrap());
        }),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("cannot be combined"), "{e}");
    // The CLI: the overview's size, and a bad level as a usage error.
    let dir = tempfile::tempdir().unwrap();
    let f = tmp(&dir, "a.vtz");
    std::fs::write(&f, &bytes).unwrap();
    let out = tmp(&dir, "o.f32");
    let o = vtz(["decode", &f, "-o", &out, "--overview", "2", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::metadata(&out).unwrap().len(), 10 * 8 * 4);
    let o = vtz(["decode", &f, "-o", &out, "-f", "--overview", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("not in 1..=30"), "{}", stderr(&o));
}
