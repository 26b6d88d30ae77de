//! Tiled files (container versions 2, 4 and 5; tests/suite/cloud.rs has versions 4's and 5's own): the bound on every sample, bytes independent of the
//! thread count, windows equal to crops of the full decode, reads limited to the tiles a
//! window touches, continuity of resampled surfaces across tile borders, and corrupt
//! indexes and tiles rejected with clear errors.

use crate::common;

use common::{Kind, bits, decode_opts, encode_opts, terrain};
use std::io::Cursor;
use vtz::{Decoder, EncodeOptions, Error, ErrorBound, Method, Raster, SampleType, Window};

fn tiled_opts(methods: &[Method], e: Option<f64>, tile: u32, threads: usize) -> EncodeOptions {
    let mut o = encode_opts(methods, e.map(ErrorBound::Abs));
    o.tile = Some(tile);
    o.threads = threads;
    o
}

fn source() -> Raster {
    terrain(Kind::Fbm, 150, 110, 7, true, SampleType::I16)
}

fn max_err(a: &Raster, b: &Raster) -> f64 {
    (0..a.len())
        .filter(|&i| a.is_valid(i))
        .map(|i| (a.data[i] - b.data[i]).abs())
        .fold(0.0, f64::max)
}

#[test]
fn every_method_round_trips_within_the_bound_over_tiles() {
    let src = source();
    for (m, e) in [
        (Method::SIBSON, 3.0),
        (Method::RESIDUAL, 2.0),
        (Method::GRID, 0.0),
        (Method::HAAR, 4.0),
        (Method::FIS, 40.0),
    ] {
        let bytes = vtz::encode(&src, &tiled_opts(&[m], Some(e), 40, 0)).unwrap();
        let info = vtz::info(&bytes, Default::default()).unwrap();
        let t = info.tiles.as_ref().expect("a tiled file");
        assert_eq!((t.cols, t.rows), (4, 3), "{}", m.name());
        // The tile's method by the name --method takes ("sibson", not the section's "sites").
        assert!(t.tiles.iter().all(|x| x.method == m.name()), "{}", m.name());
        let d = vtz::decode(&bytes).unwrap();
        assert_eq!(d.mask, src.mask, "{}: nodata kept", m.name());
        let me = max_err(&src, &d);
        assert!(me <= e, "{}: max error {me} over {e}", m.name());
        let v = Decoder::new(Cursor::new(bytes.to_vec()))
            .unwrap()
            .verify()
            .unwrap();
        // Each tile's coded samples, margins included.
        assert_eq!(v.valid, t.tiles.iter().map(|x| x.valid).sum::<u64>());
        assert!(v.valid > src.valid_count() as u64);
    }
}

#[test]
fn a_percent_bound_is_of_the_whole_rasters_range() {
    let src = source();
    let (lo, hi) = src.valid_range().unwrap();
    let mut o = tiled_opts(&[], None, 40, 0);
    o.max_error = Some(ErrorBound::PercentOfRange(2.0));
    let (bytes, rep) = vtz::encode_report(&src, &o).unwrap();
    let e = (hi - lo) * 0.02;
    assert!(rep.max_error <= e);
    assert!(max_err(&src, &vtz::decode(&bytes).unwrap()) <= e);
    let info = vtz::info(&bytes, Default::default()).unwrap();
    assert_eq!(
        info.range,
        Some((lo, hi)),
        "the file's range is the tiles' union"
    );
}

#[test]
fn bytes_and_decodes_are_the_same_for_any_thread_count() {
    let src = source();
    let first = vtz::encode(&src, &tiled_opts(&[], Some(2.0), 32, 1)).unwrap();
    for t in [2, 3, 7] {
        let b = vtz::encode(&src, &tiled_opts(&[], Some(2.0), 32, t)).unwrap();
        assert!(b == first, "{t} threads wrote other bytes");
    }
    let full = vtz::decode(&first).unwrap();
    for t in [1, 2, 5] {
        let d = vtz::decode_with(&first, &decode_opts(|o| o.threads = t)).unwrap();
        assert_eq!(bits(&d), bits(&full), "{t} threads");
    }
}

#[test]
fn a_window_is_the_crop_of_the_full_decode_bit_for_bit() {
    let src = terrain(Kind::Hill, 130, 90, 3, true, SampleType::F32);
    for m in [Method::SIBSON, Method::RESIDUAL, Method::HAAR] {
        let bytes = vtz::encode(&src, &tiled_opts(&[m], Some(1.5), 32, 0)).unwrap();
        let full = vtz::decode(&bytes).unwrap();
        let mut s = 12345u64;
        let mut rnd = |n: usize| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            ((s >> 33) % n as u64) as usize
        };
        for _ in 0..12 {
            let (x, y) = (rnd(129), rnd(89));
            let (w, h) = (1 + rnd(130 - x), 1 + rnd(90 - y));
            let win = Window {
                x,
                y,
                width: w,
                height: h,
            };
            let d = vtz::decode_with(&bytes, &decode_opts(|o| o.window = Some(win))).unwrap();
            for j in 0..h {
                for i in 0..w {
                    let a = d.data[j * w + i].to_bits();
                    let b = full.data[(y + j) * 130 + x + i].to_bits();
                    assert_eq!(a, b, "{}: window {win:?} at ({i},{j})", m.name());
                }
            }
            assert_eq!(d.georef, full.georef.as_ref().map(|g| g.window(x, y)));
        }
    }
}

#[test]
fn resampling_is_continuous_across_tile_borders() {
    let src = terrain(Kind::Hill, 96, 64, 5, false, SampleType::F32);
    for m in [Method::SIBSON, Method::RESIDUAL] {
        let bytes = vtz::encode(&src, &tiled_opts(&[m], Some(2.0), 32, 0)).unwrap();
        let d = vtz::decode(&bytes).unwrap();
        // The decoded samples of the whole, untiled and lossless: resampling interpolates
        // them as it would this file's, so the two agree bit for bit (no seam at x = 32 or
        // 64, y = 32: the tiled file is resampled as one raster).
        let whole = vtz::encode(&d, &tiled_opts(&[Method::RESIDUAL], None, 0, 0)).unwrap();
        for s in ["2", "3/2", "0.5"] {
            let at = |b: &[u8], threads: usize| {
                vtz::decode_with(
                    b,
                    &decode_opts(|o| {
                        o.scale = Some(s.parse().unwrap());
                        o.threads = threads;
                    }),
                )
                .unwrap()
            };
            let t = at(&bytes, 1);
            let sc: vtz::Scale = s.parse().unwrap();
            let (num, den) = (sc.num as usize, sc.den as usize);
            assert_eq!((t.width, t.height), (96 * num / den, 64 * num / den));
            assert_eq!(bits(&t), bits(&at(&whole, 1)), "{} at {s}", m.name());
            assert_eq!(bits(&t), bits(&at(&bytes, 4)), "{} at {s}", m.name());
        }
    }
}

#[test]
fn a_raster_within_one_tile_stays_version_1() {
    let src = source();
    let b = vtz::encode(&src, &tiled_opts(&[], Some(2.0), 512, 0)).unwrap();
    assert_eq!(u16::from_le_bytes([b[8], b[9]]), 1);
    // The default keeps rasters up to 4096 untiled.
    let b = vtz::encode(&src, &encode_opts(&[], Some(ErrorBound::Abs(2.0)))).unwrap();
    assert_eq!(u16::from_le_bytes([b[8], b[9]]), 1);
}

#[test]
fn the_default_tiles_by_sample_count_not_by_one_side() {
    // The global DEM, 4320 × 2161 (9.3 M samples): wider than 4096 but smaller than
    // a 4096² raster, which stays whole; it stays whole too (its 10 % file was 6 % larger in
    // 15 tiles). No raster is made: the decision is by size alone.
    let opts = encode_opts(&[], Some(ErrorBound::PercentOfRange(10.0)));
    assert_eq!(vtz::tile_count(4320, 2161, &opts), 1);
    assert_eq!(vtz::tile_count(4096, 4096, &opts), 1);
    assert_eq!(vtz::tile_count(100_000, 160, &opts), 1);
    // Above 4096² samples the default tiles, whatever the shape.
    assert!(vtz::tile_count(4097, 4096, &opts) > 1);
    assert!(vtz::tile_count(2000, 9000, &opts) > 1);
    // An explicit side still tiles a small raster, and 0 never tiles.
    let mut o = opts.clone();
    o.tile = Some(1024);
    assert!(vtz::tile_count(4320, 2161, &o) > 1);
    o.tile = Some(0);
    assert_eq!(vtz::tile_count(5000, 5000, &o), 1);
}

fn tiled_file() -> (Vec<u8>, vtz::TilesInfo) {
    let src = source();
    let mut o = tiled_opts(&[], Some(2.0), 40, 0);
    o.metadata = Some("{\"who\":\"test\"}".into());
    let bytes = vtz::encode(&src, &o).unwrap();
    let t = vtz::info(&bytes, Default::default())
        .unwrap()
        .tiles
        .unwrap();
    (bytes, t)
}

fn corrupt_msg(bytes: &[u8]) -> String {
    match Decoder::new(Cursor::new(bytes.to_vec())).and_then(|mut d| d.decode()) {
        Err(e @ Error::Corrupt { .. }) => e.to_string(),
        Err(e) => panic!("not a corrupt error: {e}"),
        Ok(_) => panic!("decoded a corrupt file"),
    }
}

/// Rewrite index entry `k`'s field at byte `at` (of its 56) of a version-2 file of `n`
/// tiles and fix the index checksum.
fn patch_index(bytes: &[u8], n: usize, k: usize, at: usize, value: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let start = b.len() - (8 + 56 * n);
    let e = start + 4 + 56 * k + at;
    b[e..e + value.len()].copy_from_slice(value);
    let crc = crc32(&b[start..b.len() - 4]);
    let l = b.len();
    b[l - 4..].copy_from_slice(&crc.to_le_bytes());
    b
}

fn crc32(b: &[u8]) -> u32 {
    let mut c = !0u32;
    for &x in b {
        c ^= x as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Version 2's index (at the end of the file), on its golden file: vtz no longer writes
/// version 2 but decodes it forever (tests/suite/cloud.rs checks version 4's index).
#[test]
fn corrupt_version_2_indexes_are_rejected_naming_the_tile() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/v2_kauai_tiles.vtz");
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 2);
    let t = vtz::info(&bytes, Default::default())
        .unwrap()
        .tiles
        .unwrap();
    let n = t.tiles.len();
    assert_eq!(n, 6);
    let off = |k: usize| t.tiles[k].offset;
    // An offset outside the file.
    let m = corrupt_msg(&patch_index(
        &bytes,
        n,
        3,
        0,
        &(bytes.len() as u64 * 2).to_le_bytes(),
    ));
    let w = t.tiles[3].window;
    assert!(m.contains(&format!("tile 3 (at {},{})", w.x, w.y)), "{m}");
    // Overlapping the previous tile; repeating it.
    let m = corrupt_msg(&patch_index(&bytes, n, 4, 0, &(off(4) - 1).to_le_bytes()));
    assert!(m.contains("tile 4") && m.contains("back to back"), "{m}");
    let m = corrupt_msg(&patch_index(&bytes, n, 5, 0, &off(4).to_le_bytes()));
    assert!(m.contains("tile 5"), "{m}");
    // A length beyond the file, and one beyond the limits.
    let m = corrupt_msg(&patch_index(&bytes, n, 5, 8, &u64::MAX.to_le_bytes()));
    assert!(m.contains("tile 5"), "{m}");
    let limits = vtz::Limits {
        max_section_bytes: 100,
        ..Default::default()
    };
    let e = Decoder::with_limits(Cursor::new(bytes.to_vec()), limits)
        .err()
        .unwrap();
    assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
    // A valid count above the tile's samples; a reversed range; a negative max error.
    let m = corrupt_msg(&patch_index(&bytes, n, 2, 24, &1_000_000u64.to_le_bytes()));
    assert!(m.contains("valid samples"), "{m}");
    let m = corrupt_msg(&patch_index(&bytes, n, 2, 32, &1e9f64.to_le_bytes()));
    assert!(m.contains("range"), "{m}");
    let m = corrupt_msg(&patch_index(&bytes, n, 2, 48, &(-1.0f64).to_le_bytes()));
    assert!(m.contains("max error"), "{m}");
    // A bad checksum of the index itself.
    let mut b = bytes.clone();
    let l = b.len();
    b[l - 10] ^= 1;
    assert!(corrupt_msg(&b).contains("tile index checksum"));
    // Every proper prefix.
    for k in 0..bytes.len() {
        assert!(
            Decoder::new(Cursor::new(bytes[..k].to_vec())).is_err(),
            "prefix {k}"
        );
    }
}

#[test]
fn every_proper_prefix_of_a_tiled_file_is_rejected() {
    let (bytes, _) = tiled_file();
    for n in 0..bytes.len() {
        assert!(
            Decoder::new(Cursor::new(bytes[..n].to_vec())).is_err(),
            "prefix of {n} of {} bytes opened",
            bytes.len()
        );
    }
}

#[test]
fn a_corrupt_tile_fails_naming_it_and_skip_corrupt_writes_nodata_there() {
    let (bytes, t) = tiled_file();
    let k = 6;
    let mut b = bytes.clone();
    let at = (t.tiles[k].offset + t.tiles[k].bytes / 2) as usize;
    b[at] ^= 0x55;
    let m = corrupt_msg(&b);
    let w = t.tiles[k].window;
    assert!(
        m.contains(&format!("tile 6 (at {},{})", w.x, w.y)) && m.contains("checksum"),
        "{m}"
    );
    // Windows that miss the tile still decode.
    let win = Window {
        x: 0,
        y: 0,
        width: 150,
        height: w.y - t.margin as usize,
    };
    assert!(vtz::decode_with(&b, &decode_opts(|o| o.window = Some(win))).is_ok());
    let mut d = Decoder::new(Cursor::new(b.to_vec())).unwrap();
    d.options(decode_opts(|o| o.skip_corrupt = true));
    let r = d.decode().unwrap();
    assert_eq!(d.skipped().len(), 1);
    assert!(d.skipped()[0].contains("tile 6"));
    let full = vtz::decode(&bytes).unwrap();
    let src = source();
    let (m, e) = (t.margin as usize, t.tiles[k].coded);
    let within = |x: usize, y: usize, r: Window, pad: usize| {
        x + pad >= r.x + 2 * pad
            && x + pad < r.x + r.width
            && y + pad >= r.y + 2 * pad
            && y + pad < r.y + r.height
    };
    let mut blended = 0;
    for y in 0..110 {
        for x in 0..150 {
            let i = y * 150 + x;
            if within(x, y, w, m) {
                // Only the corrupt tile codes these: nodata.
                assert!(!r.is_valid(i), "({x},{y}) should be nodata");
            } else if !within(x, y, e, 0) {
                // The corrupt tile does not code these: as in the sound file.
                assert_eq!(r.is_valid(i), full.is_valid(i));
                assert_eq!(r.data[i].to_bits(), full.data[i].to_bits());
            } else if src.is_valid(i) {
                // Its margins: the neighbours alone, still within the bound.
                assert!(
                    r.is_valid(i) && (r.data[i] - src.data[i]).abs() <= 2.0,
                    "({x},{y})"
                );
                blended += 1;
            }
        }
    }
    assert!(blended > 0);
}

#[test]
fn whole_file_requests_stay_untiled_or_are_refused_with_an_explicit_tile() {
    let src = source();
    let mut o = encode_opts(&[], None);
    o.target_bytes = Some(4000);
    o.tile = Some(32);
    let e = vtz::encode(&src, &o).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
    let mut o = tiled_opts(&[], Some(1.0), 8, 0);
    o.tile = Some(8);
    let e = vtz::encode(&src, &o).unwrap_err();
    assert!(e.to_string().contains("below the smallest"), "{e}");
}

#[test]
fn metadata_goes_to_the_global_sections_and_comes_back() {
    let mut src = source();
    src.gdal_metadata = Some("<GDALMetadata><Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item></GDALMetadata>".into());
    let bytes = vtz::encode(&src, &tiled_opts(&[Method::GRID], None, 40, 0)).unwrap();
    let info = vtz::info(&bytes, Default::default()).unwrap();
    assert_eq!(info.sections.len(), 1);
    assert_eq!(info.sections[0].name, "gdal-metadata");
    let d = vtz::decode(&bytes).unwrap();
    assert_eq!(d.gdal_metadata, src.gdal_metadata);
    assert_eq!(bits(&d), bits(&src), "lossless");
}

/// The global directory holds metadata and GDAL metadata only (FORMAT.md, versions 2, 4
/// and 5): a flat section there (or a mask, or a representation) is corrupt, for decode and
/// verify. Version 5's comes after the tile index.
#[test]
fn a_global_directory_holds_only_metadata_sections() {
    let (bytes, _) = tiled_file();
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 5);
    let hlen = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let index_len = u32::from_le_bytes(bytes[hlen + 8..hlen + 12].try_into().unwrap()) as usize;
    let dir = 20 + hlen + index_len;
    assert_eq!(
        u32::from_le_bytes(bytes[dir..dir + 4].try_into().unwrap()),
        1
    );
    assert_eq!(u16::from_le_bytes([bytes[dir + 4], bytes[dir + 5]]), 7);
    vtz::decode(&bytes).unwrap();
    for (kind, flags) in [(9u16, 1u16), (9, 0), (1, 1), (6, 0), (0x8000, 0)] {
        let mut b = bytes.clone();
        b[dir + 4..dir + 6].copy_from_slice(&kind.to_le_bytes());
        b[dir + 6..dir + 8].copy_from_slice(&flags.to_le_bytes());
        let crc = crc32(&b[dir..dir + 4 + 16]);
        b[dir + 20..dir + 24].copy_from_slice(&crc.to_le_bytes());
        let m = corrupt_msg(&b);
        assert!(m.contains("only metadata"), "type {kind}: {m}");
        let e = Decoder::new(Cursor::new(b.to_vec()))
            .and_then(|mut d| d.verify())
            .unwrap_err();
        assert!(
            matches!(e, Error::Corrupt { .. }),
            "verify, type {kind}: {e}"
        );
    }
}
