//! Every file of the shared corpus (`../shared/corpus/`), through `vtz convert` and `.vtz`:
//! originals read bit-exactly (checked against the corpus's own `.f32`), convert back into
//! their own format without change, and encode losslessly and within bounds.
//! Skipped, with a message, when `../shared/corpus` is absent.

use crate::common;

use common::{assert_same, encode_opts, shared_corpus, stderr, vtz};
use std::ffi::OsStr;
use std::path::Path;
use vtz::{EncodeOptions, ErrorBound, Method};

fn manifest(dir: &Path) -> Vec<serde_json::Value> {
    serde_json::from_slice::<Vec<serde_json::Value>>(
        &std::fs::read(dir.join("manifest.json")).unwrap(),
    )
    .unwrap()
}

/// Extra CLI options some originals need (value mapping not stored in the file).
fn read_flags(original: &str) -> Vec<&'static str> {
    if original.starts_with("srtm1_N45E013") {
        vec!["--png-offset", "-32768", "--png-nodata", "0"]
    } else if original.contains("terrainrgb") {
        // A colour PNG is read as heights only when asked.
        vec!["--from", "terrain-rgb"]
    } else {
        vec![]
    }
}

fn convert(from: &Path, to: &Path, extra: &[&str]) {
    let mut args = vec![OsStr::new("convert"), from.as_os_str(), to.as_os_str()];
    args.extend(extra.iter().map(OsStr::new));
    args.push(OsStr::new("-q"));
    let o = vtz(&args);
    assert!(
        o.status.success(),
        "convert {} -> {}: {}",
        from.display(),
        to.display(),
        stderr(&o)
    );
}

#[test]
fn originals_convert_bit_exactly() {
    let Some(dir) = shared_corpus() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let mut done = 0;
    for m in manifest(&dir) {
        let Some(orig) = m["original_file"].as_str() else {
            continue;
        };
        let name = m["name"].as_str().unwrap();
        let src = dir.join(orig);
        let flags = read_flags(orig);
        // 1. Read exactly: the original converted to raw f32 equals the corpus's f32.
        let f32_out = tmp.path().join(format!("{name}.f32"));
        convert(&src, &f32_out, &flags);
        let ours = std::fs::read(&f32_out).unwrap();
        let theirs = std::fs::read(dir.join(format!("{name}.f32"))).unwrap();
        assert!(
            ours == theirs,
            "{orig}: decoded samples differ from {name}.f32"
        );
        // 2. Written back in its own format, it reads back identically.
        let ext = Path::new(orig).extension().unwrap().to_str().unwrap();
        let again = tmp.path().join(format!("again_{name}.{ext}"));
        convert(&src, &again, &flags);
        let trgb = orig.contains("terrainrgb");
        let ro = vtz::formats::ReadOptions::default()
            .with_png_mapping(
                orig.starts_with("srtm1_N45E013")
                    .then(|| vtz::formats::PngMapping {
                        scale: 1.0,
                        offset: -32768.0,
                        nodata_code: Some(0),
                    }),
            )
            .with_format(trgb.then_some(vtz::formats::Format::TerrainRgb));
        let a = vtz::read_path(&src, &ro).unwrap();
        let again_ro = vtz::formats::ReadOptions::default()
            .with_format(trgb.then_some(vtz::formats::Format::TerrainRgb));
        let b = vtz::read_path(&again, &again_ro).unwrap();
        assert_same(&a, &b, orig);
        if ext == "hgt" {
            assert!(
                std::fs::read(&again).unwrap() == std::fs::read(&src).unwrap(),
                "{orig}: hgt bytes differ"
            );
        }
        done += 1;
    }
    assert!(done >= 12, "only {done} originals found");
}

#[test]
fn every_corpus_raster_round_trips_through_vtz() {
    let Some(dir) = shared_corpus() else { return };
    for m in manifest(&dir) {
        let name = m["name"].as_str().unwrap();
        let r = vtz::read_path(&dir.join(format!("{name}.f32")), &Default::default()).unwrap();
        let lossless = vtz::decode(&vtz::encode(&r, &EncodeOptions::default()).unwrap()).unwrap();
        assert_same(&r, &lossless, name);
        for pct in [0.1, 1.0] {
            let opts = encode_opts(&[Method::GRID], Some(ErrorBound::PercentOfRange(pct)));
            let back = vtz::decode(&vtz::encode(&r, &opts).unwrap()).unwrap();
            let c = vtz::metrics::compare(&r, &back).unwrap();
            assert!(
                c.max_error_pct <= pct,
                "{name} at {pct} %: {}",
                c.max_error_pct
            );
            assert_eq!(back.mask, r.mask, "{name}");
        }
    }
}

/// The wavelet and fractal sections on all 21 corpus rasters: Haar at 1 % and FIS at 10 %
/// meet their bound (FIS may instead say it cannot meet it), nodata survives.
#[test]
fn every_corpus_raster_meets_its_bound_with_haar_and_fis() {
    let Some(dir) = shared_corpus() else { return };
    for m in manifest(&dir) {
        let name = m["name"].as_str().unwrap();
        let r = vtz::read_path(&dir.join(format!("{name}.f32")), &Default::default()).unwrap();
        for (method, pct) in [(Method::HAAR, 1.0), (Method::FIS, 10.0)] {
            let opts = encode_opts(&[method], Some(ErrorBound::PercentOfRange(pct)));
            let bytes = match vtz::encode(&r, &opts) {
                Ok(b) => b,
                Err(e) if method == Method::FIS && e.to_string().contains("cannot meet") => {
                    continue;
                }
                Err(e) => panic!("{name} {method:?}: {e}"),
            };
            let back = vtz::decode(&bytes).unwrap();
            let c = vtz::metrics::compare(&r, &back).unwrap();
            assert!(
                c.max_error_pct <= pct,
                "{name} {method:?} at {pct} %: {}",
                c.max_error_pct
            );
            assert_eq!(back.mask, r.mask, "{name} {method:?}");
        }
    }
}
