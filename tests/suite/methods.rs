//! The four representations through the container: each meets its bound, files may carry
//! several sections for comparison, and `--section` picks one.

use crate::common;

use common::{corpus, decode_opts, encode_opts, read_corpus, stderr, tmp, vtz};
use std::path::Path;
use vtz::{ErrorBound, Method, Raster, SampleType, SectionChoice, Window};

fn crater() -> vtz::Raster {
    read_corpus("scape_crater.png")
}

#[test]
fn every_method_meets_its_bound_through_the_container() {
    let r = crater();
    for (method, pcts) in [
        (Method::FIS, &[10.0, 20.0][..]),
        (Method::HAAR, &[0.3, 1.0, 3.0][..]),
        (Method::SIBSON, &[3.0][..]),
        (Method::GRID, &[1.0][..]),
    ] {
        for &pct in pcts {
            let opts = encode_opts(&[method], Some(ErrorBound::PercentOfRange(pct)));
            let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
            assert_eq!(rep.method, method);
            let back = vtz::decode(&bytes).unwrap();
            let c = vtz::metrics::compare(&r, &back).unwrap();
            let bound = 945.0 * pct / 100.0;
            assert!(
                c.max_error <= bound && c.max_error <= rep.max_error,
                "{method:?} at {pct} %: {} > {bound}",
                c.max_error
            );
            // A window decodes to the same samples as the full decode.
            let win = Window {
                x: 17,
                y: 33,
                width: 101,
                height: 64,
            };
            let part = vtz::decode_with(&bytes, &decode_opts(|o| o.window = Some(win))).unwrap();
            for y in 0..win.height {
                for x in 0..win.width {
                    assert_eq!(
                        part.data[y * win.width + x].to_bits(),
                        back.data[(y + win.y) * back.width + x + win.x].to_bits()
                    );
                }
            }
        }
    }
}

#[test]
fn a_file_can_carry_several_sections_and_the_smallest_is_primary() {
    let r = crater();
    let opts = encode_opts(
        &[Method::SIBSON, Method::FIS, Method::HAAR],
        Some(ErrorBound::PercentOfRange(10.0)),
    );
    let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
    let info = vtz::info(&bytes, Default::default()).unwrap();
    // Crater Lake's lake is a flat region: its section comes first, then the methods'.
    assert_eq!(info.sections[0].name, "flat");
    assert!(info.sections[0].required);
    let first = 1;
    let kinds: Vec<Option<Method>> = info.sections[first..].iter().map(|e| e.method).collect();
    assert_eq!(
        kinds,
        [Some(Method::SIBSON), Some(Method::FIS), Some(Method::HAAR)]
    );
    let primary = info.primary;
    let smallest = (first..first + 3)
        .min_by_key(|&i| info.sections[i].bytes)
        .expect("three");
    assert_eq!(primary, smallest);
    assert_eq!(Some(rep.method), info.sections[primary].method);
    for (i, e) in info.sections.iter().enumerate().skip(first) {
        // Only the primary is required: a decoder without the others' methods skips them.
        assert_eq!(e.required, i == primary);
        let back = vtz::decode_with(
            &bytes,
            &decode_opts(|o| o.section = SectionChoice::Index(i)),
        )
        .unwrap();
        let c = vtz::metrics::compare(&r, &back).unwrap();
        assert!(c.max_error <= 94.5, "section {i}: {}", c.max_error);
    }
    for n in 0..bytes.len() {
        assert!(vtz::decode(&bytes[..n]).is_err(), "prefix {n}");
    }
}

#[test]
fn cli_writes_a_method_list_and_decodes_a_section_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let src = corpus("scape_crater.png");
    let out = tmp(&dir, "c.vtz");
    let o = vtz([
        "encode",
        "-q",
        "--max-error",
        "10%",
        "--method",
        "fis,haar",
        &src,
        "-o",
        &out,
    ]);
    assert!(o.status.success());
    for (name, method) in [("fis", Method::FIS), ("haar", Method::HAAR)] {
        let dec = tmp(&dir, &format!("{name}.tif"));
        let o = vtz(["decode", "-q", "--section", name, &out, "-o", &dec]);
        assert!(o.status.success(), "{}", stderr(&o));
        let back = vtz::read_path(Path::new(&dec), &Default::default()).unwrap();
        let bytes = std::fs::read(&out).unwrap();
        let info = vtz::info(&bytes, Default::default()).unwrap();
        let idx = info
            .sections
            .iter()
            .position(|e| e.method == Some(method))
            .unwrap();
        let direct = vtz::decode_with(
            &bytes,
            &decode_opts(|o| o.section = SectionChoice::Index(idx)),
        )
        .unwrap();
        assert_eq!(back.data, direct.data, "{name}");
    }
    // `info --stats` reports the FIS and Haar parameters.
    let o = vtz(["info", "--stats", "--json", &out]);
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["fis"]["k"].as_u64().unwrap() >= 2, "{j}");
    assert!(j["fis"]["iterations"].as_u64().unwrap() >= 1, "{j}");
    assert!(j["haar"]["levels"].as_u64().unwrap() >= 1, "{j}");
    // A section the file does not have: a one-line usage error.
    let o = vtz([
        "decode",
        "-q",
        "--section",
        "sibson",
        &out,
        "-o",
        &tmp(&dir, "x.tif"),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("no sibson section") && err.lines().count() == 1,
        "{err}"
    );
}

#[test]
fn fis_that_cannot_meet_a_bound_says_so() {
    let r = crater();
    let opts = encode_opts(&[Method::FIS], Some(ErrorBound::PercentOfRange(0.5)));
    let err = vtz::encode(&r, &opts).unwrap_err();
    assert!(matches!(err, vtz::Error::Unmet { .. }), "{err}");
    assert!(err.to_string().contains("cannot meet"), "{err}");
    // `best` simply leaves FIS out.
    let best = encode_opts(&[], Some(ErrorBound::PercentOfRange(0.5)));
    let (_, rep) = vtz::encode_report(&r, &best).unwrap();
    assert_ne!(rep.method, Method::FIS);
}

#[test]
fn fis_reproduces_the_papers_fixed_s_setting_without_a_bound() {
    let r = crater();
    let mut opts = encode_opts(&[Method::FIS], None);
    opts.params.fis.k = Some(16);
    opts.params.fis.s = Some(0.02);
    let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
    assert_eq!(rep.method, Method::FIS);
    let back = vtz::decode(&bytes).unwrap();
    let c = vtz::metrics::compare(&r, &back).unwrap();
    // The bound reported is the error measured on the decoded surface.
    assert_eq!(c.max_error, rep.max_error);
    // Interpolation points are exact (integer source: the code lattice).
    for y in (0..r.height).step_by(16) {
        for x in (0..r.width).step_by(16) {
            assert_eq!(
                back.data[y * r.width + x],
                r.data[y * r.width + x],
                "{x},{y}"
            );
        }
    }
    // FIS options without the fis method are a usage error.
    let mut bad = encode_opts(&[Method::SIBSON], Some(ErrorBound::PercentOfRange(5.0)));
    bad.params.fis.k = Some(8);
    assert!(matches!(
        vtz::encode(&r, &bad),
        Err(vtz::Error::InvalidArgument { .. })
    ));
}

#[test]
fn several_methods_share_one_progress_bar_that_never_runs_back() {
    // Each method reports its own 0..1; the codec gives each its slice of the whole.
    let r = common::terrain(common::Kind::Fbm, 96, 80, 3, false, vtz::SampleType::I16);
    let opts = encode_opts(
        &[Method::GRID, Method::HAAR, Method::FIS],
        Some(ErrorBound::PercentOfRange(10.0)),
    );
    let mut seen = Vec::new();
    vtz::encode_progress(&r, &opts, &mut |f| seen.push(f)).unwrap();
    assert!(seen.len() > 3, "haar and fis report progress: {seen:?}");
    assert!(seen.iter().all(|f| (0.0..=1.0).contains(f)), "{seen:?}");
    assert!(
        seen.windows(2).all(|w| w[0] <= w[1]),
        "never back: {seen:?}"
    );
    // FIS, the last of three, reports in the last third.
    assert!(seen.iter().any(|&f| f > 2.0 / 3.0), "{seen:?}");
}

/// Integer sources keep their type's range: a sample at the top of the range must not
/// decode past it (u8 255 with a grid step of 13 once decoded as 260), for every method.
#[test]
fn integer_extremes_decode_inside_the_type() {
    for (st, lo, hi) in [
        (SampleType::U8, 0.0, 255.0),
        (SampleType::I16, -32768.0, 32767.0),
        (SampleType::U16, 0.0, 65535.0),
        (SampleType::I32, -2147483648.0, 2147483647.0),
    ] {
        for n in [33usize, 100] {
            let data: Vec<f64> = (0..n)
                .map(|i| match i % 5 {
                    0 => hi,
                    1 => lo,
                    2 => hi - 1.0,
                    _ => lo + 2.0,
                })
                .collect();
            let r = Raster::from_values(n, 1, data, None, st).unwrap();
            for m in [Method::GRID, Method::HAAR, Method::SIBSON] {
                for e in [1.0, 6.0, 100.0] {
                    let Ok(bytes) = vtz::Encoder::new()
                        .max_error(ErrorBound::Abs(e))
                        .method(m)
                        .encode(&r)
                    else {
                        continue; // a method may refuse (Unmet); the others must hold
                    };
                    let back = vtz::decode(&bytes).unwrap();
                    for (i, (&a, &b)) in r.data.iter().zip(&back.data).enumerate() {
                        assert!(
                            b >= lo && b <= hi && (a - b).abs() <= e,
                            "{st:?} {} e={e} n={n}: sample {i} {a} decoded as {b}",
                            m.name()
                        );
                    }
                }
            }
        }
    }
}

/// `Decoder::max_error` reads the bound each method stored, without decoding: the encoder's
/// report, 0 for lossless.
#[test]
fn decoder_reports_the_stored_bound() {
    let r = crater();
    for (m, e) in [
        (Method::GRID, 0.0),
        (Method::GRID, 3.0),
        (Method::HAAR, 3.0),
        (Method::SIBSON, 9.0),
        (Method::FIS, 95.0),
        (Method::RESIDUAL, 2.0),
    ] {
        let b = if e == 0.0 {
            None
        } else {
            Some(ErrorBound::Abs(e))
        };
        let (bytes, rep) = vtz::encode_report(&r, &encode_opts(&[m], b)).unwrap();
        let mut dec = vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec())).unwrap();
        let stored = dec.max_error().unwrap();
        assert_eq!(stored, rep.max_error, "{}", m.name());
        assert!(stored <= e, "{}: {stored} > {e}", m.name());
    }
}
