//! Golden files: one `.vtz` per format version (and representation), decoded forever.
//!
//! Each `tests/golden/NAME.vtz` decodes to exactly `NAME.expected.f32` (little-endian f32,
//! nodata samples hold the header's nodata value). Regenerate only deliberately, for a new
//! format version: `VTZ_BLESS_GOLDEN=1 cargo test --test suite golden::` writes files that are
//! missing; existing golden files are never rewritten.

use crate::common;

use common::{decode_opts, encode_opts, read_corpus};
use std::path::{Path, PathBuf};
use vtz::{EncodeOptions, ErrorBound, Method, Window};

fn dir() -> PathBuf {
    common::golden_dir()
}

/// The source of every golden file but the coast ones: a 64×48 window of the Kauai SRTM
/// tile with voids.
fn source() -> vtz::Raster {
    window(448, 960)
}

/// The source of the coast golden files: a 64×48 window of Kauai with voids, land and
/// 1 474 samples of sea (exact zeros, a flat region).
fn coast() -> vtz::Raster {
    window(376, 968)
}

fn window(x: usize, y: usize) -> vtz::Raster {
    window_of(x, y, 64, 48)
}

fn window_of(x: usize, y: usize, width: usize, height: usize) -> vtz::Raster {
    let bytes = vtz::encode(
        &read_corpus("srtm3_N22W160_kauai.hgt"),
        &EncodeOptions::default(),
    )
    .unwrap();
    let opts = decode_opts(|o| {
        o.window = Some(Window {
            x,
            y,
            width,
            height,
        })
    });
    vtz::decode_with(&bytes, &opts).unwrap()
}

/// GDAL_METADATA of the gdal-metadata golden file: a description with a non-ASCII letter
/// (the ʻokina), a unit and a dataset item, as GDAL writes them.
const GDAL_METADATA: &str = "<GDALMetadata>\n  <Item name=\"DataType\">Generic</Item>\n  \
    <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">Elevation (SRTM3, Kaua\u{2bb}i)</Item>\n  \
    <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item>\n</GDALMetadata>\n";

/// (name, options, bound checked against the source (0 = identical), the source's GDAL
/// metadata).
fn cases() -> Vec<(&'static str, EncodeOptions, f64, Option<&'static str>)> {
    vec![
        (
            "v1_kauai_crop_grid",
            encode_opts(&[Method::GRID], None),
            0.0,
            None,
        ),
        (
            "v1_kauai_crop_sites",
            encode_opts(&[Method::SIBSON], Some(ErrorBound::Abs(8.0))),
            8.0,
            None,
        ),
        (
            "v1_kauai_crop_fis",
            encode_opts(&[Method::FIS], Some(ErrorBound::Abs(150.0))),
            150.0,
            None,
        ),
        (
            "v1_kauai_crop_haar",
            encode_opts(&[Method::HAAR], Some(ErrorBound::Abs(8.0))),
            8.0,
            None,
        ),
        (
            "v1_kauai_crop_gdalmeta",
            encode_opts(&[Method::GRID], None),
            0.0,
            Some(GDAL_METADATA),
        ),
        (
            // Written when effort 1 took the rule's predictor (lossless → the weighted scan;
            // effort 1 now writes the fast coding: golden files are never re-blessed).
            "v1_kauai_crop_residual",
            {
                let mut o = encode_opts(&[Method::RESIDUAL], None);
                o.effort = Some(1);
                o
            },
            0.0,
            None,
        ),
        (
            "v1_kauai_crop_residual_lossy",
            encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(2.0))),
            2.0,
            None,
        ),
        (
            "v1_kauai_crop_residual_exceptions",
            encode_opts(&[Method::RESIDUAL], None),
            0.0,
            None,
        ),
        (
            // The fast coding (coding 2, effort 2; written when effort 1 wrote it),
            // lossless, with stencil weights.
            "v1_kauai_crop_residual_fast",
            effort(encode_opts(&[Method::RESIDUAL], None), 2),
            0.0,
            None,
        ),
        (
            // The fast coding with narrower coarse-level bins (coding 3).
            "v1_kauai_crop_residual_fast_tight",
            effort(
                encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(60.0))),
                2,
            ),
            60.0,
            None,
        ),
        (
            // The lane coding (coding 4, effort 1), lossless, with stencil weights.
            "v1_kauai_crop_residual_lanes",
            effort(encode_opts(&[Method::RESIDUAL], None), 1),
            0.0,
            None,
        ),
        (
            // The lane coding with narrower coarse-level bins (coding 5).
            "v1_kauai_crop_residual_lanes_tight",
            effort(
                encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(60.0))),
                1,
            ),
            60.0,
            None,
        ),
        (
            // Wide bins: the encoder narrows them on coarse levels (coding 1).
            "v1_kauai_crop_residual_tight",
            encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(60.0))),
            60.0,
            None,
        ),
        (
            "v1_kauai_coast_flat",
            encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(8.0))),
            8.0,
            None,
        ),
    ]
}

/// Whether golden file `path` is missing and may be written (with VTZ_BLESS_GOLDEN set;
/// without it a missing golden file fails the test).
fn missing(path: &Path) -> bool {
    if path.exists() {
        return false;
    }
    assert!(
        std::env::var_os("VTZ_BLESS_GOLDEN").is_some(),
        "{} is missing (VTZ_BLESS_GOLDEN=1 writes it)",
        path.display()
    );
    true
}

/// `o` with effort `k`.
fn effort(mut o: EncodeOptions, k: u8) -> EncodeOptions {
    o.effort = Some(k);
    o
}

/// The source of golden file `name`.
fn source_of(name: &str) -> vtz::Raster {
    if name.contains("coast") {
        coast()
    } else if name.contains("exceptions") {
        exceptions()
    } else {
        source()
    }
}

/// The source of the exceptions golden file: the crop as float32, every 37th valid sample
/// raised by 0.25 m (whole metres but for a few: voids filled by interpolation look so).
fn exceptions() -> vtz::Raster {
    let s = source();
    let mut k = 0;
    let data: Vec<f64> = (0..s.len())
        .map(|i| {
            if !s.is_valid(i) {
                return f64::NAN;
            }
            k += 1;
            s.data[i] + if k % 37 == 0 { 0.25 } else { 0.0 }
        })
        .collect();
    let mut r = vtz::Raster::from_values(64, 48, data, s.nodata, vtz::SampleType::F32).unwrap();
    r.georef = s.georef;
    r
}

fn as_f32_bytes(r: &vtz::Raster) -> Vec<u8> {
    let fill = r.nodata.unwrap_or(f64::NAN);
    (0..r.len())
        .flat_map(|i| (if r.is_valid(i) { r.data[i] } else { fill } as f32).to_le_bytes())
        .collect()
}

#[test]
fn golden_files_decode_to_their_expected_samples() {
    let bless = std::env::var_os("VTZ_BLESS_GOLDEN").is_some();
    for (name, opts, bound, gdal_metadata) in cases() {
        let vtz_path = dir().join(format!("{name}.vtz"));
        let exp_path = dir().join(format!("{name}.expected.f32"));
        if !vtz_path.exists() {
            assert!(
                bless,
                "{} is missing (VTZ_BLESS_GOLDEN=1 writes it)",
                vtz_path.display()
            );
            let mut src = source_of(name);
            src.gdal_metadata = gdal_metadata.map(String::from);
            let bytes = vtz::encode(&src, &opts).unwrap();
            std::fs::write(&vtz_path, &bytes).unwrap();
            std::fs::write(&exp_path, as_f32_bytes(&vtz::decode(&bytes).unwrap())).unwrap();
        }
        let bytes = std::fs::read(&vtz_path).unwrap();
        let r = vtz::decode(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((r.width, r.height), (64, 48), "{name}");
        assert_eq!(r.nodata, Some(-32768.0), "{name}");
        let st = if name.contains("exceptions") {
            vtz::SampleType::F32
        } else {
            vtz::SampleType::I16
        };
        assert_eq!(r.sample_type, st, "{name}");
        let g = r.georef.as_ref().expect("georef");
        assert_eq!(g.epsg, Some(4326));
        assert_eq!(r.gdal_metadata.as_deref(), gdal_metadata, "{name}");
        assert!(r.valid_count() < r.len(), "{name}: the crop has voids");
        let expected = std::fs::read(&exp_path).unwrap();
        assert!(
            as_f32_bytes(&r) == expected,
            "{name}: decoded samples differ from {}",
            exp_path.display()
        );
        // And the decode is within the bound it claims, against the source window.
        let c = vtz::metrics::compare(&source_of(name), &r).unwrap();
        assert_eq!((c.lost, c.invented), (0, 0));
        if bound == 0.0 {
            assert!(c.identical, "{name}");
        } else {
            assert!(c.max_error <= bound, "{name}: {}", c.max_error);
        }
    }
}

#[test]
fn every_proper_prefix_of_the_golden_files_is_rejected() {
    for (name, _, _, _) in cases() {
        let bytes = std::fs::read(dir().join(format!("{name}.vtz"))).unwrap();
        for n in 0..bytes.len() {
            assert!(
                vtz::decode(&bytes[..n]).is_err(),
                "{name}: prefix of {n} bytes decoded"
            );
        }
    }
}

#[test]
fn the_gdal_metadata_section_is_optional_and_strict_about_utf8() {
    use vtz::internals::container::{self, SectionKind};
    let bytes = std::fs::read(dir().join("v1_kauai_crop_gdalmeta.vtz")).unwrap();
    let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
    let s = info.sections.last().unwrap();
    assert_eq!(
        (s.name.as_str(), s.code, s.required),
        ("gdal-metadata", 8, false)
    );
    assert_eq!(s.bytes, GDAL_METADATA.len() as u64);
    let full = vtz::decode(&bytes).unwrap();

    // A decoder that predates type 8 sees an unknown optional section: it skips it and
    // decodes the same samples (simulated with a private type code no decoder knows).
    let mut c = container::read(&bytes, vtz::Limits::default()).unwrap();
    let i = c
        .sections
        .iter()
        .position(|s| s.kind == SectionKind::GDAL_METADATA)
        .unwrap();
    c.sections[i].kind = SectionKind(0x8001);
    let skipped = vtz::decode(&container::write(&c.header, &c.sections)).unwrap();
    assert_eq!(skipped.gdal_metadata, None);
    assert_eq!(as_f32_bytes(&skipped), as_f32_bytes(&full));

    // Invalid UTF-8 (checksums recomputed, so only the text is wrong) is a corrupt file.
    c.sections[i].kind = SectionKind::GDAL_METADATA;
    c.sections[i].payload = b"<GDALMetadata>\xff</GDALMetadata>".to_vec();
    let e = vtz::decode(&container::write(&c.header, &c.sections)).unwrap_err();
    assert!(matches!(e, vtz::Error::Corrupt { .. }), "{e}");
    assert!(
        e.to_string().contains("gdal-metadata") && e.to_string().contains("UTF-8"),
        "{e}"
    );
}

#[test]
fn the_residual_and_flat_golden_files_cover_both_predictors_and_every_new_coding() {
    let read = |name: &str| std::fs::read(dir().join(format!("{name}.vtz"))).unwrap();
    let mut predictors = Vec::new();
    for name in [
        "v1_kauai_crop_residual",
        "v1_kauai_crop_residual_lossy",
        "v1_kauai_coast_flat",
    ] {
        let bytes = read(name);
        let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
        let p = &info.sections[info.primary];
        assert_eq!((p.name.as_str(), p.code), ("residual", 6), "{name}");
        predictors.push(bytes[p.offset as usize + 1]);
    }
    predictors.sort();
    predictors.dedup();
    // The fast files: codings 2 (with stencil weights) and 3; the lane files: 4 and 5.
    for (name, coding, weighted) in [
        ("v1_kauai_crop_residual_fast", 2, true),
        ("v1_kauai_crop_residual_fast_tight", 3, false),
        // (The crop's lane coding fits no stencil worth its bytes: the banded lane file
        // below has them.)
        ("v1_kauai_crop_residual_lanes", 4, false),
        ("v1_kauai_crop_residual_lanes_tight", 5, false),
    ] {
        let bytes = read(name);
        let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
        let p = info.sections[info.primary].offset as usize;
        assert_eq!((bytes[p], bytes[p + 1]), (coding, 0), "{name}");
        assert_eq!(
            bytes[p + 3] > 0,
            weighted,
            "{name}: weight sets {}",
            bytes[p + 3]
        );
    }
    // The tight file narrows coarse-level bins (coding 1).
    let bytes = read("v1_kauai_crop_residual_tight");
    let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
    let p = info.sections[info.primary].offset as usize;
    assert_eq!((bytes[p], bytes[p + 1]), (1, 0), "coding 1, interpolation");
    // The exceptions file stores every 37th valid sample verbatim (offset 4: their count).
    let bytes = read("v1_kauai_crop_residual_exceptions");
    let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
    let p = info.sections[info.primary].offset as usize;
    let x = u32::from_le_bytes(bytes[p + 4..p + 8].try_into().unwrap());
    let valid = exceptions().valid_count() as u32;
    assert_eq!(x, valid / 37, "exceptions");
    assert_eq!(
        predictors,
        [0, 1],
        "interpolation (0) and weighted (1) predictors"
    );
    // The coast file holds the flat section (type 9) and a context-coded mask (coding 1).
    let bytes = read("v1_kauai_coast_flat");
    let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
    let names: Vec<_> = info
        .sections
        .iter()
        .map(|s| (s.name.as_str(), s.code, s.required))
        .collect();
    assert_eq!(names[..2], [("mask", 1, true), ("flat", 9, true)]);
    assert_eq!(bytes[info.sections[0].offset as usize], 1, "mask coding 1");
    assert_eq!(bytes[info.sections[1].offset as usize], 0, "flat coding 0");
    // Its sea decodes to exact zeros.
    let r = vtz::decode(&bytes).unwrap();
    let src = coast();
    let sea = (0..src.len())
        .filter(|&i| src.is_valid(i) && src.data[i] == 0.0)
        .count();
    let kept = (0..src.len())
        .filter(|&i| src.is_valid(i) && src.data[i] == 0.0 && r.data[i] == 0.0)
        .count();
    assert!(
        sea > 1400 && kept >= 1024 && kept + 60 >= sea,
        "{kept} of {sea} sea samples exact"
    );
}

/// The flat section's coding 1 (8×8 blocks): a 128×96 window of Kauai's coast with voids
/// and 6 191 samples of sea, residual within 8 m. The sea's whole blocks decode to exact
/// zeros; the older coding-0 file (`v1_kauai_coast_flat`) still decodes as it did.
#[test]
fn the_block_coded_flat_golden_file_decodes_to_its_expected_samples() {
    let name = "v1_kauai_coast_flat_blocks";
    let vtz_path = dir().join(format!("{name}.vtz"));
    let exp_path = dir().join(format!("{name}.expected.f32"));
    let src = window_of(368, 928, 128, 96);
    if missing(&vtz_path) {
        let bytes = vtz::encode(
            &src,
            &encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(8.0))),
        )
        .unwrap();
        std::fs::write(&vtz_path, &bytes).unwrap();
        std::fs::write(&exp_path, as_f32_bytes(&vtz::decode(&bytes).unwrap())).unwrap();
    }
    let bytes = std::fs::read(&vtz_path).unwrap();
    let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
    let names: Vec<_> = info
        .sections
        .iter()
        .map(|s| (s.name.as_str(), s.code))
        .collect();
    assert_eq!(names[..2], [("mask", 1), ("flat", 9)]);
    assert_eq!(bytes[info.sections[1].offset as usize], 1, "flat coding 1");
    let r = vtz::decode(&bytes).unwrap();
    assert_eq!(
        as_f32_bytes(&r),
        std::fs::read(&exp_path).unwrap(),
        "{name}: decoded samples differ"
    );
    let c = vtz::metrics::compare(&src, &r).unwrap();
    assert_eq!((c.lost, c.invented), (0, 0));
    assert!(c.max_error <= 8.0, "{}", c.max_error);
    // Every sea sample of a whole 8×8 block of sea decodes to exactly 0.
    let w = src.width;
    let whole = |i: usize| {
        let (x0, y0) = ((i % w) / 8 * 8, (i / w) / 8 * 8);
        (y0..y0 + 8)
            .all(|y| (x0..x0 + 8).all(|x| src.is_valid(y * w + x) && src.data[y * w + x] == 0.0))
    };
    let blocks: Vec<usize> = (0..src.len()).filter(|&i| whole(i)).collect();
    assert!(
        blocks.len() > 4096,
        "{} samples in sea blocks",
        blocks.len()
    );
    assert!(blocks.iter().all(|&i| r.data[i] == 0.0));
    for n in 0..bytes.len() {
        assert!(
            vtz::decode(&bytes[..n]).is_err(),
            "prefix of {n} bytes decoded"
        );
    }
}

/// The fast and lane codings' bands: the whole Kauai tile (1201², voids, sea) within 20 m,
/// whose finest passes are cut into 3 and 2 bands of rows. Its 1.4 M decoded samples are
/// pinned by the CRC-32 of their f32 bytes (`.expected.crc32`), not stored.
#[test]
fn the_banded_fast_golden_file_decodes_to_its_expected_samples() {
    for (name, eff, coding) in [
        ("v1_kauai_residual_fast_bands", 2, 3),
        ("v1_kauai_residual_lanes_bands", 1, 5),
    ] {
        banded(name, eff, coding);
    }
}

fn banded(name: &str, eff: u8, coding: u8) {
    let vtz_path = dir().join(format!("{name}.vtz"));
    let exp_path = dir().join(format!("{name}.expected.crc32"));
    let src = read_corpus("srtm3_N22W160_kauai.hgt");
    let crc = |r: &vtz::Raster| format!("{:08x}\n", crc32fast::hash(&as_f32_bytes(r)));
    if missing(&vtz_path) {
        let bytes = vtz::encode(
            &src,
            &effort(
                encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(20.0))),
                eff,
            ),
        )
        .unwrap();
        std::fs::write(&vtz_path, &bytes).unwrap();
        std::fs::write(&exp_path, crc(&vtz::decode(&bytes).unwrap())).unwrap();
    }
    let bytes = std::fs::read(&vtz_path).unwrap();
    let info = vtz::info(&bytes, vtz::Limits::default()).unwrap();
    let p = info.sections[info.primary].offset as usize;
    assert_eq!(bytes[p], coding, "{name}: coding {coding}");
    assert!(bytes[p + 3] > 0, "{name}: stencil weights");
    for threads in [1, 2] {
        let r = vtz::decode_with(&bytes, &decode_opts(|o| o.threads = threads)).unwrap();
        assert_eq!(
            crc(&r),
            std::fs::read_to_string(&exp_path).unwrap(),
            "{name}: decoded samples differ ({threads} threads)"
        );
        let c = vtz::metrics::compare(&src, &r).unwrap();
        assert_eq!((c.lost, c.invented), (0, 0));
        assert!(c.max_error <= 20.0, "{}", c.max_error);
    }
    for n in (0..bytes.len())
        .step_by(61)
        .chain(bytes.len() - 40..bytes.len())
    {
        assert!(
            vtz::decode(&bytes[..n]).is_err(),
            "prefix of {n} bytes decoded"
        );
    }
}

/// The version-2 golden file: a 96×64 window of Kauai's coast (voids, sea, land) cut into
/// 3 × 2 tiles of 32², each coded by `best` within 8 m, with metadata and GDAL metadata in
/// the global sections.
#[test]
fn the_tiled_golden_file_decodes_to_its_expected_samples() {
    let name = "v2_kauai_tiles";
    let vtz_path = dir().join(format!("{name}.vtz"));
    let exp_path = dir().join(format!("{name}.expected.f32"));
    if missing(&vtz_path) {
        let mut src = window_of(360, 952, 96, 64);
        src.gdal_metadata = Some(GDAL_METADATA.into());
        let mut opts = encode_opts(&[], Some(ErrorBound::Abs(8.0)));
        opts.tile = Some(32);
        opts.metadata = Some("{\"golden\":\"v2\"}".into());
        let bytes = vtz::encode(&src, &opts).unwrap();
        std::fs::write(&vtz_path, &bytes).unwrap();
        std::fs::write(&exp_path, as_f32_bytes(&vtz::decode(&bytes).unwrap())).unwrap();
    }
    let bytes = std::fs::read(&vtz_path).unwrap();
    assert_eq!(
        u16::from_le_bytes([bytes[8], bytes[9]]),
        2,
        "a version-2 file"
    );
    let info = vtz::info(&bytes, Default::default()).unwrap();
    let t = info.tiles.as_ref().expect("tiles");
    assert_eq!(
        (t.cols, t.rows, t.tile_width, t.tile_height),
        (3, 2, 32, 32)
    );
    assert_eq!(info.sections.len(), 2, "metadata and gdal-metadata");
    let r = vtz::decode(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!((r.width, r.height), (96, 64));
    assert_eq!(r.nodata, Some(-32768.0));
    assert_eq!(r.sample_type, vtz::SampleType::I16);
    assert_eq!(r.georef.as_ref().and_then(|g| g.epsg), Some(4326));
    assert!(r.valid_count() < r.len(), "the window has voids");
    let expected = std::fs::read(&exp_path).unwrap();
    assert!(
        as_f32_bytes(&r) == expected,
        "{name}: decoded samples differ"
    );
    vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec()))
        .unwrap()
        .verify()
        .unwrap();
}

/// The version-4 and version-5 golden files: the version-2 file's window, tiles, bound and
/// sections, laid out for range reads (index first, progressive chunks; version 5 with
/// every tile's head before the tails), coded by `best` (version 4: the range-coded residual
/// codings, then the default; version 5: the default, the lane coding), by the fast coding
/// (effort 2) and by the lane coding (effort 1). Each overview of them is pinned too: it
/// reads a prefix of each block.
#[test]
fn the_version_4_and_5_golden_files_decode_to_their_expected_samples() {
    for (name, effort, version) in [
        ("v4_kauai_tiles", None, 4u16),
        ("v4_kauai_tiles_fast", Some(2u8), 4),
        ("v4_kauai_tiles_lanes", Some(1u8), 4),
        ("v5_kauai_tiles", None, 5),
    ] {
        // Both with the residual layer (interpolation, range-coded or fast), whose tiles
        // are progressive: several chunks each.
        let vtz_path = dir().join(format!("{name}.vtz"));
        let exp_path = dir().join(format!("{name}.expected.f32"));
        let ovr_path = dir().join(format!("{name}.overviews.f32"));
        let ovr = |bytes: &[u8], k: u32| {
            let o = common::decode_opts(|o| o.overview = Some(k));
            vtz::decode_with(bytes, &o).unwrap_or_else(|e| panic!("{name} overview {k}: {e}"))
        };
        if missing(&vtz_path) {
            let mut src = window_of(360, 952, 96, 64);
            src.gdal_metadata = Some(GDAL_METADATA.into());
            let mut opts = encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(2.0)));
            opts.tile = Some(32);
            opts.effort = effort;
            opts.metadata = Some(format!("{{\"golden\":\"v{version}\"}}"));
            let bytes = vtz::encode(&src, &opts).unwrap();
            std::fs::write(&vtz_path, &bytes).unwrap();
            std::fs::write(&exp_path, as_f32_bytes(&vtz::decode(&bytes).unwrap())).unwrap();
            let mut o = Vec::new();
            for k in 1..=3 {
                o.extend(as_f32_bytes(&ovr(&bytes, k)));
            }
            std::fs::write(&ovr_path, o).unwrap();
        }
        let bytes = std::fs::read(&vtz_path).unwrap();
        assert_eq!(
            u16::from_le_bytes([bytes[8], bytes[9]]),
            version,
            "{name}: a version-{version} file"
        );
        let info = vtz::info(&bytes, Default::default()).unwrap();
        assert_eq!(info.version, version);
        let t = info.tiles.as_ref().expect("tiles");
        assert_eq!(
            (t.cols, t.rows, t.tile_width, t.tile_height),
            (3, 2, 32, 32)
        );
        assert_eq!(info.sections.len(), 2, "metadata and gdal-metadata");
        // Chunk counts from the index (each entry: 40 bytes, then 8 per chunk).
        let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let mut at = 24 + h;
        let mut chunks = Vec::new();
        for _ in 0..6 {
            chunks.push(bytes[at + 4]);
            at += 40 + 8 * bytes[at + 4] as usize;
        }
        assert!(
            chunks.iter().filter(|&&c| c > 1).count() >= 4,
            "{name}: chunks {chunks:?}"
        );
        let r = vtz::decode(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((r.width, r.height), (96, 64));
        assert_eq!(r.nodata, Some(-32768.0));
        assert!(r.valid_count() < r.len(), "the window has voids");
        let expected = std::fs::read(&exp_path).unwrap();
        assert!(
            as_f32_bytes(&r) == expected,
            "{name}: decoded samples differ"
        );
        let mut got = Vec::new();
        for k in 1..=3 {
            got.extend(as_f32_bytes(&ovr(&bytes, k)));
        }
        let expected = std::fs::read(&ovr_path).unwrap();
        assert!(got == expected, "{name}: overviews 1-3 differ");
        vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec()))
            .unwrap()
            .verify()
            .unwrap();
        for n in 0..bytes.len() {
            assert!(
                vtz::decode(&bytes[..n]).is_err(),
                "{name}: prefix of {n} bytes decoded"
            );
        }
    }
}

/// The source of the point-set golden file: 300 points on a 0.01 m grid (coordinates
/// `k / 100`, so the positions are lossless) in UTM 4N, with two columns — `z`, a smooth
/// surface with noise, and `intensity`, integers — and 24 points repeating an earlier
/// point's position with other values (shared positions). A fixed LCG makes it the same on
/// every machine.
fn points_source() -> vtz::PointSet {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = move |n: u64| {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (s >> 33) % n
    };
    let (mut x, mut y, mut z, mut it): (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for i in 0..300 {
        let (kx, ky) = if i >= 276 {
            // A shared position: an earlier point's, other values.
            let j = next(276) as usize;
            (
                (x[j] * 100.0f64).round() as i64,
                (y[j] * 100.0f64).round() as i64,
            )
        } else {
            (
                45_000_000 + next(4000) as i64,
                244_000_000 + next(3000) as i64,
            )
        };
        let (xf, yf) = (kx as f64 / 100.0, ky as f64 / 100.0);
        let smooth = 100.0 + 5.0 * (xf / 7.0).sin() + 3.0 * (yf / 5.0).cos();
        x.push(xf);
        y.push(yf);
        z.push(((smooth + next(100) as f64 / 200.0) * 1000.0).round() / 1000.0);
        it.push(next(256) as f64);
    }
    vtz::PointSet {
        x,
        y,
        names: vec!["z".into(), "intensity".into()],
        values: vec![z, it],
        epsg: Some(32604),
        wkt: None,
    }
}

fn points_encode() -> Vec<u8> {
    let o = vtz::PointsOptions::new(ErrorBound::Abs(0.1))
        .column_bound("intensity", ErrorBound::Abs(2.0));
    vtz::encode_points(&points_source(), &o, &mut |_| {})
        .unwrap()
        .0
}

/// `x,y,z,intensity` per decoded point, each value as Rust prints an f64 (shortest text that
/// reads back to the same bits).
fn points_csv(p: &vtz::PointSet) -> String {
    let mut s = format!("x,y,{}\n", p.names.join(","));
    for i in 0..p.len() {
        s += &format!("{},{}", p.x[i], p.y[i]);
        for c in &p.values {
            s += &format!(",{}", c[i]);
        }
        s += "\n";
    }
    s
}

#[test]
fn the_point_set_golden_file_decodes_to_its_expected_points() {
    let name = "v3_points";
    let vtz_path = dir().join(format!("{name}.vtz"));
    let exp_path = dir().join(format!("{name}.expected.csv"));
    if missing(&vtz_path) {
        let bytes = points_encode();
        let p = vtz::decode_points(&bytes, &vtz::DecodePoints::new()).unwrap();
        std::fs::write(&vtz_path, &bytes).unwrap();
        std::fs::write(&exp_path, points_csv(&p)).unwrap();
    }
    let bytes = std::fs::read(&vtz_path).unwrap();
    assert!(bytes.len() < 8192, "the golden file stays small");
    assert_eq!(
        u16::from_le_bytes([bytes[8], bytes[9]]),
        3,
        "a version-3 file"
    );
    // (a) The decode, bit for bit.
    let p = vtz::decode_points(&bytes, &vtz::DecodePoints::new())
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(p.len(), 300);
    assert_eq!(p.names, ["z", "intensity"]);
    assert_eq!(p.epsg, Some(32604));
    let expected = std::fs::read_to_string(&exp_path).unwrap();
    let got = points_csv(&p);
    for (i, (g, e)) in got.lines().zip(expected.lines()).enumerate() {
        assert_eq!(
            g,
            e,
            "{name}: line {} differs from {}",
            i + 1,
            exp_path.display()
        );
    }
    assert_eq!(got.lines().count(), expected.lines().count());
    // The decode holds the bounds at every source point (matched by position and value:
    // the decode is in position order, not input order).
    let src = points_source();
    let info = vtz::points_info(&bytes, Default::default()).unwrap();
    assert!(info.columns[0].max_error <= 0.1 && info.columns[1].max_error <= 2.0);
    assert!(info.levels.len() > 1, "several levels");
    let mut sv: Vec<(i64, i64)> = (0..src.len())
        .map(|i| {
            (
                (src.x[i] * 100.0).round() as i64,
                (src.y[i] * 100.0).round() as i64,
            )
        })
        .collect();
    let mut dv: Vec<(i64, i64)> = (0..p.len())
        .map(|i| {
            (
                (p.x[i] * 100.0).round() as i64,
                (p.y[i] * 100.0).round() as i64,
            )
        })
        .collect();
    sv.sort_unstable();
    dv.sort_unstable();
    assert_eq!(sv, dv, "the same positions, with their multiplicities");
    assert!(sv.windows(2).any(|w| w[0] == w[1]), "some shared positions");
    // (b) The encoder still writes these bytes: any change of the format shows here.
    assert!(
        points_encode() == bytes,
        "{name}: re-encoding the source gives other bytes"
    );
    // (c) Every proper prefix is rejected.
    for n in 0..bytes.len() {
        assert!(
            vtz::decode_points(&bytes[..n], &vtz::DecodePoints::new()).is_err(),
            "{name}: prefix of {n} bytes decoded"
        );
    }
    // (d) A flipped byte in the header or in either section fails its checksum. The
    // sections are the file's last bytes, positions then point-sites.
    assert_eq!(info.sections.len(), 2);
    let mut at = bytes.len() - info.sections.iter().map(|s| s.1 as usize).sum::<usize>();
    let mut offsets = vec![20];
    for (_, len) in &info.sections {
        offsets.extend([at, at + *len as usize / 2, at + *len as usize - 1]);
        at += *len as usize;
    }
    for o in offsets {
        let mut b = bytes.clone();
        b[o] ^= 0x10;
        let e = vtz::decode_points(&b, &vtz::DecodePoints::new())
            .expect_err(&format!("{name}: byte {o} flipped decoded"));
        assert!(e.to_string().contains("checksum"), "{name}: byte {o}: {e}");
    }
}
