//! Container and grid-section tests: round trips, bounds, truncation, corruption, garbage.

mod common;

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
