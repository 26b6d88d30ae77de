//! Container and grid-section tests: round trips, bounds, truncation, corruption, garbage.

use crate::common;

use common::{Kind, Rng, assert_same, decode_opts, encode_opts};
use proptest::prelude::*;
use vtz::internals::container::{self, Header, SF_REQUIRED, Section, SectionKind};
use vtz::{
    EncodeOptions, Error, ErrorBound, GeoKeys, Georef, Limits, Method, Raster, RasterType,
    SampleType, ValueMapping,
};

/// A deterministic rough terrain (with nodata holes) and a UTM georef.
fn terrain(w: usize, h: usize, st: SampleType, holes: bool) -> Raster {
    let mut r = common::terrain(Kind::Fbm, w, h, 12345, holes, st);
    r.georef = Some(Georef {
        origin: [600000.0, 5200000.0],
        pixel_size: [30.0, 30.0],
        raster_type: RasterType::Area,
        epsg: Some(32632),
        wkt: None,
        geokeys: Some(GeoKeys {
            directory: vec![1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32632],
            doubles: vec![],
            ascii: "WGS 84 / UTM zone 32N|".into(),
        }),
    });
    r
}

fn assert_bits_equal(a: &Raster, b: &Raster) {
    assert_same(a, b, "round trip");
    assert_eq!(a.mapping, b.mapping);
}

/// Whether a section of this type may be the primary one (any but the mask, metadata,
/// gdal-metadata and flat regions: the container rejects those as primary).
fn can_be_primary(k: SectionKind) -> bool {
    k != SectionKind::MASK
        && k != SectionKind::METADATA
        && k != SectionKind::GDAL_METADATA
        && k != SectionKind::FLAT
}

/// Whether this version knows the type: mask, grid, sites, fis, haar, residual, metadata,
/// gdal-metadata, flat regions.
fn is_known(k: SectionKind) -> bool {
    (1..=9).contains(&k.code())
}

/// The bytes every `.vtz` file starts with.
fn magic() -> Vec<u8> {
    let r = Raster::from_values(1, 1, vec![0.0], None, SampleType::I16).unwrap();
    vtz::encode(&r, &EncodeOptions::default()).unwrap()[..8].to_vec()
}

#[test]
fn lossless_round_trip_every_sample_type() {
    for st in [
        SampleType::I16,
        SampleType::U16,
        SampleType::I32,
        SampleType::F32,
        SampleType::F64,
    ] {
        for holes in [false, true] {
            let r = terrain(67, 41, st, holes);
            let bytes = vtz::encode(&r, &EncodeOptions::default()).unwrap();
            let back = vtz::decode(&bytes).unwrap();
            assert_bits_equal(&r, &back);
        }
    }
}

#[test]
fn lossy_bound_holds_and_integers_stay_integers() {
    for st in [SampleType::I16, SampleType::F32, SampleType::F64] {
        for e in [0.25, 0.5, 1.0, 3.7, 50.0] {
            let r = terrain(53, 47, st, true);
            let opts = encode_opts(&[Method::GRID], Some(ErrorBound::Abs(e)));
            let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
            let back = vtz::decode(&bytes).unwrap();
            let c = vtz::metrics::compare(&r, &back).unwrap();
            assert!(c.max_error <= e, "{st:?} e={e}: {}", c.max_error);
            assert!(rep.max_error <= e);
            assert_eq!(back.mask, r.mask);
            if st.is_integer() {
                assert!(
                    back.data
                        .iter()
                        .enumerate()
                        .all(|(i, v)| !back.is_valid(i) || v.fract() == 0.0)
                );
            }
            if st == SampleType::F32 {
                assert!(
                    back.data
                        .iter()
                        .all(|&v| v.is_nan() || v as f32 as f64 == v)
                );
            }
        }
    }
}

#[test]
fn percent_bound_is_of_the_value_range() {
    let r = terrain(40, 40, SampleType::F32, false);
    let (lo, hi) = r.valid_range().unwrap();
    let opts = encode_opts(&[Method::GRID], Some(ErrorBound::parse("1%").unwrap()));
    let back = vtz::decode(&vtz::encode(&r, &opts).unwrap()).unwrap();
    let c = vtz::metrics::compare(&r, &back).unwrap();
    assert!(c.max_error <= (hi - lo) * 0.01);
    assert!(c.max_error_pct <= 1.0);
}

#[test]
fn error_bound_parsing() {
    assert_eq!(ErrorBound::parse("2.5").unwrap(), ErrorBound::Abs(2.5));
    assert_eq!(
        ErrorBound::parse("1%").unwrap(),
        ErrorBound::PercentOfRange(1.0)
    );
    for bad in ["", "-1", "abc", "1%%", "nan", "inf"] {
        assert!(
            matches!(ErrorBound::parse(bad), Err(Error::InvalidArgument { .. })),
            "{bad}"
        );
    }
}

#[test]
fn all_nodata_and_tiny_rasters() {
    let r = Raster::from_values(3, 2, vec![f64::NAN; 6], None, SampleType::F32).unwrap();
    let back = vtz::decode(&vtz::encode(&r, &EncodeOptions::default()).unwrap()).unwrap();
    assert_eq!(back.valid_count(), 0);
    for (w, h) in [(1, 1), (1, 9), (9, 1), (2, 2)] {
        let r = Raster::from_values(
            w,
            h,
            (0..w * h).map(|i| i as f64 * 3.0).collect(),
            None,
            SampleType::I16,
        )
        .unwrap();
        let back = vtz::decode(&vtz::encode(&r, &EncodeOptions::default()).unwrap()).unwrap();
        assert_bits_equal(&r, &back);
    }
}

#[test]
fn every_proper_prefix_is_an_error() {
    let r = terrain(23, 19, SampleType::F32, true);
    let mut opts = EncodeOptions::default();
    opts.metadata = Some("{\"a\":1}".into());
    let bytes = vtz::encode(&r, &opts).unwrap();
    for n in 0..bytes.len() {
        match vtz::decode(&bytes[..n]) {
            Err(Error::Corrupt { .. }) => {}
            other => panic!("prefix of {n} bytes: {other:?}"),
        }
        assert!(vtz::info(&bytes[..n], Limits::default()).is_err());
    }
    assert!(vtz::decode(&bytes).is_ok());
}

#[test]
fn every_single_byte_flip_is_detected() {
    let r = terrain(17, 13, SampleType::I16, true);
    let bytes = vtz::encode(&r, &EncodeOptions::default()).unwrap();
    for i in 0..bytes.len() {
        for mask in [0x01u8, 0x80, 0xff] {
            let mut b = bytes.clone();
            b[i] ^= mask;
            assert!(
                vtz::decode(&b).is_err(),
                "flip {mask:#x} at byte {i} was not detected"
            );
        }
    }
}

#[test]
fn trailing_bytes_and_bad_magic_are_rejected() {
    let r = terrain(8, 8, SampleType::I16, false);
    let mut bytes = vtz::encode(&r, &EncodeOptions::default()).unwrap();
    bytes.push(0);
    assert!(matches!(vtz::decode(&bytes), Err(Error::Corrupt { .. })));
    let e = vtz::decode(b"II*\0 this is a tiff").unwrap_err();
    assert!(e.to_string().contains("not a vtz file"), "{e}");
}

fn header(w: u32, h: u32) -> Header {
    Header {
        width: w,
        height: h,
        sample_type: SampleType::F32,
        primary: 0,
        mapping: ValueMapping::default(),
        nodata: None,
        range: Some((0.0, 1.0)),
        georef: None,
    }
}

#[test]
fn unknown_sections_are_skipped_unless_required() {
    let r = terrain(10, 10, SampleType::I16, false);
    let bytes = vtz::encode(&r, &EncodeOptions::default()).unwrap();
    let mut c = container::read(&bytes, Limits::default()).unwrap();
    c.sections.push(Section {
        kind: SectionKind(900),
        flags: 0,
        payload: vec![1, 2, 3],
    });
    let with_optional = container::write(&c.header, &c.sections);
    assert_bits_equal(&r, &vtz::decode(&with_optional).unwrap());
    c.sections.last_mut().unwrap().flags = SF_REQUIRED;
    let with_required = container::write(&c.header, &c.sections);
    assert!(matches!(
        vtz::decode(&with_required),
        Err(Error::Unsupported { .. })
    ));
    c.sections.last_mut().unwrap().flags = 0x8000;
    assert!(matches!(
        vtz::decode(&container::write(&c.header, &c.sections)),
        Err(Error::Unsupported { .. })
    ));
}

#[test]
fn absurd_sizes_hit_limits_without_allocating() {
    let h = header(2_000_000_000, 2_000_000_000);
    let bytes = container::write(
        &h,
        &[Section {
            kind: SectionKind(2), // grid
            flags: SF_REQUIRED,
            payload: vec![],
        }],
    );
    assert!(matches!(
        vtz::decode(&bytes),
        Err(Error::LimitExceeded { .. })
    ));
    let small = decode_opts(|o| {
        o.limits = Limits {
            max_samples: 50,
            ..Default::default()
        }
    });
    let r = terrain(10, 10, SampleType::I16, false);
    let bytes = vtz::encode(&r, &EncodeOptions::default()).unwrap();
    assert!(matches!(
        vtz::decode_with(&bytes, &small),
        Err(Error::LimitExceeded { .. })
    ));
}

#[test]
fn out_of_range_header_fields_are_rejected() {
    let good = header(4, 4);
    let body = good.to_bytes();
    // sample type 9, unknown flag bit, zero scale, min > max
    let mut cases = Vec::new();
    let mut b = body.clone();
    b[8] = 9;
    cases.push(b);
    let mut b = body.clone();
    b[9] |= 0x80;
    cases.push(b);
    let mut b = body.clone();
    b[12..20].copy_from_slice(&0f64.to_le_bytes());
    cases.push(b);
    let mut b = body.clone();
    b[28..36].copy_from_slice(&5f64.to_le_bytes());
    cases.push(b);
    let mut b = body.clone();
    b[0..4].copy_from_slice(&0u32.to_le_bytes());
    cases.push(b);
    for (k, b) in cases.iter().enumerate() {
        assert!(Header::from_bytes(b).is_err(), "case {k}");
    }
    assert_eq!(Header::from_bytes(&body).unwrap(), good);
}

proptest! {
    #![proptest_config(common::proptest_config(64))]

    #[test]
    fn container_round_trips_random_sections(
        secs in proptest::collection::vec((1u16..2000, proptest::bool::ANY, proptest::collection::vec(any::<u8>(), 0..300)), 0..8),
        w in 1u32..5000, h in 1u32..5000,
        nodata in proptest::option::of(-1e6f64..1e6),
    ) {
        let mut hd = header(w, h);
        hd.nodata = nodata;
        let sections: Vec<Section> = secs.into_iter().map(|(code, req, payload)| Section {
            kind: SectionKind::from_code(code), flags: if req { SF_REQUIRED } else { 0 }, payload,
        }).collect();
        // The primary must name a representation section: point it at one if there is one.
        hd.primary = sections.iter().position(|s| can_be_primary(s.kind)).unwrap_or(0) as u16;
        let bytes = container::write(&hd, &sections);
        let valid_primary = sections.is_empty() || sections.get(hd.primary as usize).is_some_and(|s| can_be_primary(s.kind));
        let has_required_unknown = sections.iter().any(|s| !is_known(s.kind) && s.flags & SF_REQUIRED != 0);
        match container::read(&bytes, Limits::default()) {
            Ok(c) => {
                prop_assert!(valid_primary && !has_required_unknown);
                prop_assert_eq!(c.header, hd);
                prop_assert_eq!(c.sections, sections);
            }
            Err(Error::Unsupported { .. }) => prop_assert!(has_required_unknown),
            Err(e) => prop_assert!(!valid_primary, "{e}"),
        }
    }

    #[test]
    fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = vtz::decode(&bytes);
        let mut with_magic = magic();
        with_magic.extend_from_slice(&bytes);
        let _ = vtz::decode(&with_magic);
    }

    #[test]
    fn random_rasters_round_trip_within_bound(
        w in 1usize..40, h in 1usize..40,
        vals in proptest::collection::vec(prop_oneof![4 => -500.0f64..3000.0, 1 => Just(f64::NAN)], 1600),
        e in prop_oneof![Just(0.0), 0.01f64..100.0],
        float in proptest::bool::ANY,
    ) {
        let st = if float { SampleType::F32 } else { SampleType::I16 };
        let data: Vec<f64> = vals[..w * h].iter().map(|&v| if float { v as f32 as f64 } else { v.round() }).collect();
        let r = Raster::from_values(w, h, data, None, st).unwrap();
        let opts = encode_opts(&[Method::GRID], (e > 0.0).then_some(ErrorBound::Abs(e)));
        let bytes = vtz::encode(&r, &opts).unwrap();
        let back = vtz::decode(&bytes).unwrap();
        let again = vtz::decode(&bytes).unwrap();
        prop_assert_eq!(back.mask.clone(), r.mask.clone());
        for i in 0..r.len() {
            if r.is_valid(i) {
                prop_assert!((back.data[i] - r.data[i]).abs() <= e);
                prop_assert_eq!(back.data[i].to_bits(), again.data[i].to_bits());
            }
        }
    }
}

#[test]
fn float_samples_half_a_step_between_levels_stay_quantized() {
    // Values exactly between two quantization levels, at a magnitude where f32 rounding of
    // the reconstruction matters: the grid must stay lossy and within the bound.
    let mut rng = Rng(1);
    let data: Vec<f64> = (0..40_000)
        .map(|_| (1000.0 + rng.unit() * 100.0) as f32 as f64)
        .collect();
    let r = Raster::from_values(200, 200, data, None, SampleType::F32).unwrap();
    for e in [0.1, 0.01, 0.3] {
        let opts = encode_opts(&[Method::GRID], Some(ErrorBound::Abs(e)));
        let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
        assert!(rep.max_error > 0.0, "e={e}: fell back to lossless");
        let back = vtz::decode(&bytes).unwrap();
        assert!(vtz::metrics::compare(&r, &back).unwrap().max_error <= e);
    }
}

// ------------------------------------------------ stored values off the sample type's lattice

/// A version-1 i16 file with flat regions (a plateau at 800 coded within 1 by the residual
/// layer): its container, the flat section's index.
fn i16_file_with_flat_regions() -> (File, usize) {
    // A constant 80 × 96 block (flat regions have at least 4096 samples) beside a slope.
    let data = (0..128 * 96)
        .map(|i| {
            if i % 128 < 80 {
                800.0
            } else {
                (200 + i % 128 + (i / 128) % 7) as f64
            }
        })
        .collect();
    let r = Raster::from_values(128, 96, data, None, SampleType::I16).unwrap();
    let bytes = vtz::encode(
        &r,
        &encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(1.0))),
    )
    .unwrap();
    let c = container::read(&bytes, Limits::default()).unwrap();
    let flat = c
        .sections
        .iter()
        .position(|s| s.kind == SectionKind::FLAT)
        .expect("a flat section");
    (
        File {
            header: c.header,
            sections: c.sections,
        },
        flat,
    )
}

/// A file's header and sections, to edit and write back (checksums recomputed).
#[derive(Clone)]
struct File {
    header: Header,
    sections: Vec<Section>,
}

/// `vtz verify`, `vtz decode -o x.tif` and `-o x.f32` of `file` each exit 1 with one line
/// that contains every one of `words`, and leave no output behind.
fn refused_by_the_cli(file: &[u8], words: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let path = common::tmp(&dir, "hostile.vtz");
    std::fs::write(&path, file).unwrap();
    let mut runs = vec![(vec!["verify".to_string(), path.clone()], None)];
    for ext in ["tif", "f32"] {
        let out = common::tmp(&dir, &format!("x.{ext}"));
        runs.push((
            vec!["decode".into(), path.clone(), "-o".into(), out.clone()],
            Some(out),
        ));
    }
    for (args, out) in runs {
        let o = common::vtz(&args);
        let err = common::stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        // `verify` reports each file on stdout ("FILE: FAILED: why"), its summary on stderr.
        let why = if out.is_none() {
            String::from_utf8_lossy(&o.stdout).into_owned()
        } else {
            err.clone()
        };
        assert_eq!(why.trim_end().lines().count(), 1, "{args:?}: {why}");
        for w in words {
            assert!(why.contains(w), "{args:?}: '{w}' not in: {why}");
        }
        if let Some(out) = out {
            let left: Vec<_> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n != "hostile.vtz")
                .collect();
            assert!(left.is_empty(), "{args:?} left {left:?} ({out})");
        }
    }
}

/// Issue 35, item 15: a flat region's value must be a value of the file's sample type. An
/// i16 file whose flat section (checksums right) gives a region the f64 value 2.1e-314
/// was decoded (`verify` said ok, a `.tif` rounded it, a `.f32` exited 2); it is corrupt.
#[test]
fn a_flat_region_value_off_the_sample_types_lattice_is_corrupt() {
    let (c, flat) = i16_file_with_flat_regions();
    // The region values follow coding, 3 reserved bytes, the count and two u64 counts.
    let regions = u32::from_le_bytes(c.sections[flat].payload[4..8].try_into().unwrap()) as usize;
    assert!(regions >= 1);
    let good = container::write(&c.header, &c.sections);
    assert!(vtz::decode(&good).is_ok());
    for (v, mapping) in [
        (2.1e-314f64, None),
        (800.5, None),
        (40000.0, None),
        // On the integers but not on a mapped lattice: codes × 0.5 − 10.
        (
            801.25,
            Some(ValueMapping {
                scale: 0.5,
                offset: -10.0,
            }),
        ),
    ] {
        let mut c = c.clone();
        if let Some(m) = mapping {
            c.header.mapping = m;
            // The range must stay on the mapped lattice (it is checked too).
            c.header.range = Some((-10.0, 800.0));
        }
        let k = 24 + 8 * (regions - 1);
        c.sections[flat].payload[k..k + 8].copy_from_slice(&v.to_le_bytes());
        let bad = container::write(&c.header, &c.sections);
        let e = vtz::decode(&bad).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{v}: {e}");
        let msg = e.to_string();
        assert!(
            msg.contains("flat section") && msg.contains(&format!("{v:?}")),
            "{msg}"
        );
        if mapping.is_none() {
            assert!(msg.contains("i16"), "{msg}");
        }
    }
    let mut c = c.clone();
    let k = 24 + 8 * (regions - 1);
    c.sections[flat].payload[k..k + 8].copy_from_slice(&2.1e-314f64.to_le_bytes());
    refused_by_the_cli(
        &container::write(&c.header, &c.sections),
        &["flat section", "2.1e-314", "i16"],
    );
}

/// The header's range (min, max of the valid samples) must be two values of the sample
/// type: 2.5 in an i16 file, a value off a mapped u16 lattice, or one no f32 holds is corrupt;
/// the encoder refuses a raster whose extreme samples are not values of its type.
#[test]
fn a_header_range_off_the_sample_types_lattice_is_corrupt() {
    let (c, _) = i16_file_with_flat_regions();
    let (lo, hi) = c.header.range.unwrap();
    for (range, st, mapping) in [
        ((lo, hi + 0.5), SampleType::I16, ValueMapping::default()),
        ((lo - 0.25, hi), SampleType::I16, ValueMapping::default()),
        ((lo, 40000.0), SampleType::I16, ValueMapping::default()),
        (
            (-32768.0, 0.1),
            SampleType::U16,
            ValueMapping {
                scale: 1.0,
                offset: -32768.0,
            },
        ),
    ] {
        let mut c = c.clone();
        c.header.range = Some(range);
        c.header.sample_type = st;
        c.header.mapping = mapping;
        let bad = container::write(&c.header, &c.sections);
        let e = vtz::decode(&bad).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{range:?}: {e}");
        assert!(e.to_string().contains("not a value of"), "{e}");
    }
    let mut c = c.clone();
    c.header.range = Some((lo, hi + 0.5));
    refused_by_the_cli(
        &container::write(&c.header, &c.sections),
        &["maximum", &format!("{:?}", hi + 0.5), "i16"],
    );
    // f32: a range end no f32 holds.
    let r = common::terrain(Kind::Fbm, 20, 20, 1, false, SampleType::F32);
    let bytes = vtz::encode(&r, &EncodeOptions::default()).unwrap();
    let mut c = container::read(&bytes, Limits::default()).unwrap();
    c.header.range = Some((0.1, 1000.0));
    let e = vtz::decode(&container::write(&c.header, &c.sections)).unwrap_err();
    assert!(
        e.to_string().contains("minimum 0.1 is not a value of f32"),
        "{e}"
    );
    // The encoder writes only values of the type, even for a raster built with others (an
    // i16 raster holding 2.5 as its minimum, an f32 one holding f64 numbers): it refuses
    // (lossless) or writes a file that decodes, its range rounded to the type as its samples.
    let mut data = vec![7.0; 100];
    data[17] = 2.5;
    let r = Raster::from_values(10, 10, data, None, SampleType::I16).unwrap();
    assert!(vtz::encode(&r, &EncodeOptions::default()).is_err());
    let grid = vtz::encode(&r, &encode_opts(&[Method::GRID], None)).unwrap_err();
    assert!(
        grid.to_string()
            .contains("sample 17 (row 1, column 7): the value 2.5 is not a value of i16"),
        "{grid}"
    );
    let bytes = vtz::encode(&r, &encode_opts(&[], Some(ErrorBound::Abs(1.0)))).unwrap();
    let back = vtz::decode(&bytes).unwrap();
    assert!(
        back.data.iter().all(|&v| v.fract() == 0.0),
        "{:?}",
        back.data
    );
    let data: Vec<f64> = (0..100).map(|i| 0.1 * i as f64).collect();
    let r = Raster::from_values(10, 10, data, None, SampleType::F32).unwrap();
    let bytes = vtz::encode(&r, &encode_opts(&[], Some(ErrorBound::Abs(0.01)))).unwrap();
    assert!(vtz::decode(&bytes).is_ok());
}

/// A tiled file's per-tile range (in the tile index, checksum recomputed) must be two
/// values of the sample type.
#[test]
fn a_tile_range_off_the_sample_types_lattice_is_corrupt() {
    let r = common::terrain(Kind::Fbm, 300, 200, 4, false, SampleType::I16);
    let mut o = encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(1.0)));
    o.tile = Some(128);
    let bytes = vtz::encode(&r, &o).unwrap();
    assert!(vtz::decode(&bytes).is_ok());
    // Version 5: the index follows the header (its length in the header's last 8 bytes,
    // before the split): the tile count N, N entries (40 bytes, min at +16, then 8 per
    // chunk), a CRC.
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 5);
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let start = 20 + h;
    let len = u32::from_le_bytes(bytes[h + 8..h + 12].try_into().unwrap()) as usize;
    let n = u32::from_le_bytes(bytes[start..start + 4].try_into().unwrap()) as usize;
    assert!(n >= 4, "{n} tiles");
    let mut bad = bytes.clone();
    let mut at = start + 4;
    for _ in 0..n - 1 {
        at += 40 + 8 * bad[at + 4] as usize;
    }
    bad[at + 16..at + 24].copy_from_slice(&0.5f64.to_le_bytes());
    let end = start + len - 4;
    let crc = crc32fast::hash(&bad[start..end]);
    bad[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    let e = vtz::decode(&bad).unwrap_err();
    assert!(matches!(e, Error::Corrupt { .. }), "{e}");
    assert!(
        e.to_string().contains("minimum 0.5 is not a value of i16"),
        "{e}"
    );
    refused_by_the_cli(&bad, &["tile index", "0.5", "i16"]);
}
