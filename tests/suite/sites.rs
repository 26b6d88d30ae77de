//! The sites (Voronoi/Sibson) method: hard bound, determinism, windows, prefixes, bad input.

use crate::common;

use common::{Kind, Rng, bits, decode_opts, encode_opts, terrain};
use proptest::prelude::*;
use vtz::internals::container;
use vtz::{EncodeOptions, Error, ErrorBound, Method, Raster, SampleType, Scale, Window};

fn sites_opts(e: f64) -> EncodeOptions {
    encode_opts(&[Method::SIBSON], Some(ErrorBound::Abs(e)))
}

fn check_bound(r: &Raster, back: &Raster, e: f64) {
    assert_eq!(back.mask, r.mask);
    for i in 0..r.len() {
        if r.is_valid(i) {
            let d = (back.data[i] - r.data[i]).abs();
            assert!(d <= e, "sample {i}: error {d} > {e}");
        }
    }
}

proptest! {
    #![proptest_config(common::proptest_config(24))]

    #[test]
    fn bound_holds_and_decoding_is_deterministic(
        kind in prop_oneof![Just(Kind::Fbm), Just(Kind::Plateau), Just(Kind::Cliff), Just(Kind::Constant)],
        w in 1usize..48, h in 1usize..48, seed in any::<u64>(), holes in any::<bool>(), float in any::<bool>(),
        e in prop_oneof![Just(0.5), Just(1.0), 2.0f64..40.0],
    ) {
        let st = if float { SampleType::F32 } else { SampleType::I16 };
        let r = terrain(kind, w, h, seed, holes, st);
        let bytes = vtz::encode(&r, &sites_opts(e)).unwrap();
        let back = vtz::decode(&bytes).unwrap();
        check_bound(&r, &back, e);
        prop_assert_eq!(bits(&back), bits(&vtz::decode(&bytes).unwrap()));
        for threads in [1, 3] {
            let t = vtz::decode_with(&bytes, &decode_opts(|o| o.threads = threads)).unwrap();
            prop_assert_eq!(bits(&back), bits(&t));
        }
        // Windows stitched together give the same samples as the whole.
        if w >= 2 && h >= 2 {
            let (wx, wy) = (w / 2, h / 2);
            for win in [
                Window { x: 0, y: 0, width: wx, height: wy },
                Window { x: wx, y: 0, width: w - wx, height: wy },
                Window { x: 0, y: wy, width: wx, height: h - wy },
                Window { x: wx, y: wy, width: w - wx, height: h - wy },
            ] {
                let part = vtz::decode_with(&bytes, &decode_opts(|o| o.window = Some(win))).unwrap();
                for yy in 0..win.height {
                    for xx in 0..win.width {
                        let a = part.data[yy * win.width + xx];
                        let b = back.data[(win.y + yy) * w + win.x + xx];
                        prop_assert_eq!(a.to_bits(), b.to_bits());
                    }
                }
            }
        }
    }
}

#[test]
fn tiny_rasters() {
    for (w, h) in [(1, 1), (1, 7), (7, 1), (2, 2), (3, 2)] {
        let r = terrain(Kind::Fbm, w, h, 9, false, SampleType::I16);
        let back = vtz::decode(&vtz::encode(&r, &sites_opts(1.0)).unwrap()).unwrap();
        check_bound(&r, &back, 1.0);
    }
    // Every sample nodata.
    let r = Raster::from_values(4, 3, vec![f64::NAN; 12], None, SampleType::F32).unwrap();
    let back = vtz::decode(&vtz::encode(&r, &sites_opts(1.0)).unwrap()).unwrap();
    assert_eq!(back.valid_count(), 0);
}

#[test]
fn prefixes_are_coarser_levels_and_sites_budget_is_kept() {
    let r = terrain(Kind::Fbm, 120, 90, 5, true, SampleType::F32);
    let bytes = vtz::encode(&r, &sites_opts(0.8)).unwrap();
    let full = vtz::decode(&bytes).unwrap();
    let mut last = f64::INFINITY;
    for k in 1..=6 {
        let lvl = vtz::decode_with(&bytes, &decode_opts(|o| o.levels = Some(k))).unwrap();
        let c = vtz::metrics::compare(&r, &lvl).unwrap();
        assert_eq!(c.lost + c.invented, 0);
        assert!(
            c.rmse <= last * 1.5 + 1e-9,
            "level {k}: rmse {} after {last}",
            c.rmse
        );
        last = c.rmse;
    }
    let c = vtz::metrics::compare(&r, &full).unwrap();
    assert!(c.max_error <= 0.8);
    for n in [4, 50, 300] {
        let mut opts = encode_opts(&[Method::SIBSON], None);
        opts.params.sibson.sites = Some(n);
        let (_, rep) = vtz::encode_report(&r, &opts).unwrap();
        let st = rep.stats.unwrap();
        let (sites, hull) = (st.count("sites").unwrap(), st.count("hull").unwrap());
        assert!(
            sites <= (n as u64).max(hull),
            "{} sites for a budget of {n}",
            sites
        );
        let part = vtz::decode_with(&bytes, &decode_opts(|o| o.sites = Some(n)));
        if n < 16 {
            // Fewer than the first level (the hull) is refused, not silently raised.
            assert!(matches!(part, Err(vtz::Error::InvalidArgument { .. })));
        } else {
            assert_eq!(part.unwrap().valid_count(), r.valid_count());
        }
    }
}

#[test]
fn corrupted_and_truncated_sites_sections_are_errors() {
    let r = terrain(Kind::Cliff, 40, 30, 3, true, SampleType::I16);
    let bytes = vtz::encode(&r, &sites_opts(2.0)).unwrap();
    for n in 0..bytes.len() {
        assert!(vtz::decode(&bytes[..n]).is_err(), "prefix {n}");
    }
    // Rewrite the section with garbage (valid checksums) so the section decoder itself sees it.
    let c = container::read(&bytes, Default::default()).unwrap();
    let p = c.header.primary as usize;
    let mut rng = Rng(7);
    for trial in 0..300 {
        let mut cc = c.clone();
        let payload = &mut cc.sections[p].payload;
        let s = rng.next();
        let at = (s >> 33) as usize % payload.len();
        payload[at] ^= 1 << ((s >> 20) % 8);
        if trial % 3 == 0 {
            let keep = (s >> 40) as usize % payload.len();
            payload.truncate(keep);
        }
        let b = container::write(&cc.header, &cc.sections);
        match vtz::decode(&b) {
            Ok(back) => assert_eq!(back.mask, r.mask),
            Err(Error::Corrupt { .. }) | Err(Error::LimitExceeded { .. }) => {}
            Err(e) => panic!("unexpected error kind: {e}"),
        }
    }
}

#[test]
fn sibson_method_without_a_stopping_rule_is_refused() {
    let r = terrain(Kind::Fbm, 10, 10, 1, false, SampleType::I16);
    let e = vtz::encode(&r, &encode_opts(&[Method::SIBSON], None)).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
}

#[test]
fn size_target_is_met_with_the_smallest_bound_that_fits() {
    let r = terrain(Kind::Fbm, 64, 48, 11, false, SampleType::F32);
    for target in [300u64, 1500, 6000] {
        let mut opts = EncodeOptions::default();
        opts.target_bytes = Some(target);
        let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
        assert!(bytes.len() as u64 <= target, "{} > {target}", bytes.len());
        let back = vtz::decode(&bytes).unwrap();
        assert!(vtz::metrics::compare(&r, &back).unwrap().max_error <= rep.max_error + 1e-9);
    }
    let mut tiny = EncodeOptions::default();
    tiny.target_bytes = Some(10);
    assert!(matches!(
        vtz::encode(&r, &tiny),
        Err(Error::InvalidArgument { .. })
    ));
}

#[test]
fn scaled_decoding_samples_the_same_surface() {
    let mut r = terrain(Kind::Fbm, 50, 40, 21, true, SampleType::F32);
    r.georef = Some(vtz::Georef {
        origin: [1000.0, 2000.0],
        pixel_size: [10.0, 10.0],
        raster_type: vtz::RasterType::Area,
        epsg: Some(32633),
        wkt: None,
        geokeys: None,
    });
    let bytes = vtz::encode(&r, &sites_opts(1.5)).unwrap();
    let base = vtz::decode(&bytes).unwrap();
    let dec = |s: &str| {
        vtz::decode_with(
            &bytes,
            &decode_opts(|o| o.scale = Some(vtz::Scale::parse(s).unwrap())),
        )
        .unwrap()
    };
    let one = dec("1");
    assert_eq!(bits(&one), bits(&base));
    // GDAL's layout: ⌊w·s⌋ × ⌊h·s⌋ over the same extent, from the same corner.
    let up = dec("2");
    assert_eq!((up.width, up.height), (100, 80));
    let g = up.georef.as_ref().unwrap();
    assert_eq!(g.pixel_size, [5.0, 5.0]);
    assert_eq!(g.origin, [1000.0, 2000.0]);
    let down = dec("0.5");
    assert_eq!((down.width, down.height), (25, 20));
    // At odd scales output centres fall on source samples: output 3x + 1 is source x at 3,
    // output i is source 3i + 1 at 1/3.
    let up3 = dec("3");
    assert_eq!((up3.width, up3.height), (150, 120));
    let down3 = dec("1/3");
    assert_eq!((down3.width, down3.height), (16, 13));
    for y in 0..40 {
        for x in 0..50 {
            let i = y * 50 + x;
            if !base.is_valid(i) {
                continue;
            }
            let j = (3 * y + 1) * 150 + 3 * x + 1;
            if up3.is_valid(j) {
                assert!(
                    (up3.data[j] - base.data[i]).abs() < 1e-3,
                    "({x},{y}): {} vs {}",
                    up3.data[j],
                    base.data[i]
                );
            }
            let k = y / 3 * 16 + x / 3;
            if x % 3 == 1 && y % 3 == 1 && x / 3 < 16 && down3.is_valid(k) {
                assert!((down3.data[k] - base.data[i]).abs() < 1e-3);
            }
        }
    }
    // Interpolated samples lie between their neighbours' range (Sibson is a convex combination).
    let (lo, hi) = r.valid_range().unwrap();
    assert!(
        up.data
            .iter()
            .enumerate()
            .all(|(i, &v)| !up.is_valid(i) || (lo - 1.5..=hi + 1.5).contains(&v))
    );
    assert!(Scale::parse("0").is_err() && Scale::parse("x").is_err());
}

/// A raster of several 64-row chunks (the unit threads take from a shared queue, in no
/// fixed order): every thread count and windows cut across chunks decode to the same bits.
#[test]
fn decode_is_the_same_for_any_thread_count_and_window() {
    let r = terrain(Kind::Fbm, 300, 290, 21, true, SampleType::F32);
    let bytes = vtz::encode(&r, &sites_opts(2.0)).unwrap();
    let one = vtz::decode_with(&bytes, &decode_opts(|o| o.threads = 1)).unwrap();
    check_bound(&r, &one, 2.0);
    for threads in [2, 3, 4, 7] {
        let t = vtz::decode_with(&bytes, &decode_opts(|o| o.threads = threads)).unwrap();
        assert_eq!(bits(&one), bits(&t), "{threads} threads");
    }
    let mut rng = Rng(5);
    for _ in 0..6 {
        let (x, y) = (rng.below(250) as usize, rng.below(200) as usize);
        let (w, h) = (
            1 + rng.below(300 - x as u64) as usize,
            1 + rng.below(290 - y as u64) as usize,
        );
        let win = Window {
            x,
            y,
            width: w,
            height: h,
        };
        let part = vtz::decode_with(
            &bytes,
            &decode_opts(|o| {
                o.window = Some(win);
                o.threads = 3;
            }),
        )
        .unwrap();
        for yy in 0..h {
            for xx in 0..w {
                let a = part.data[yy * w + xx].to_bits();
                let b = one.data[(y + yy) * 300 + x + xx].to_bits();
                assert_eq!(a, b, "window {win:?} at ({xx}, {yy})");
            }
        }
    }
}
