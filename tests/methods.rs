//! The four representations through the container: each meets its bound, files may carry
//! several sections for comparison, and `--section` picks one.

use std::path::Path;
use std::process::Command;
use vtz::container::SectionKind;
use vtz::{DecodeOptions, EncodeOptions, ErrorBound, Method, Window};

fn crater() -> vtz::Raster {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/scape_crater.png");
    vtz::raster::read_path(&p, &Default::default()).unwrap()
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vtz"))
}

#[test]
fn every_method_meets_its_bound_through_the_container() {
    let r = crater();
    for (method, pcts) in [
        (Method::Fis, &[10.0, 20.0][..]),
        (Method::Haar, &[0.3, 1.0, 3.0][..]),
        (Method::Sibson, &[3.0][..]),
        (Method::Grid, &[1.0][..]),
    ] {
        for &pct in pcts {
            let opts = EncodeOptions {
                method,
                max_error: Some(ErrorBound::PercentOfRange(pct)),
                ..Default::default()
            };
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
            let part = vtz::decode_with(
                &bytes,
                &DecodeOptions {
                    window: Some(win),
                    ..Default::default()
                },
            )
            .unwrap();
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
    let opts = EncodeOptions {
        method: Method::Sibson,
        also: vec![Method::Fis, Method::Haar],
        max_error: Some(ErrorBound::PercentOfRange(10.0)),
        ..Default::default()
    };
    let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
    let info = vtz::info(&bytes, Default::default()).unwrap();
    let kinds: Vec<SectionKind> = info.sections.iter().map(|e| e.kind).collect();
    assert_eq!(
        kinds,
        [SectionKind::Sites, SectionKind::Fis, SectionKind::Haar]
    );
    let primary = info.header.primary as usize;
    let smallest = (0..3)
        .min_by_key(|&i| info.sections[i].length)
        .expect("three");
    assert_eq!(primary, smallest);
    assert_eq!(vtz::section_kind(rep.method), kinds[primary]);
    for (i, e) in info.sections.iter().enumerate() {
        // Only the primary is required: a decoder without the others' methods skips them.
        assert_eq!(e.flags & vtz::container::SF_REQUIRED != 0, i == primary);
        let back = vtz::decode_with(
            &bytes,
            &DecodeOptions {
                section: Some(i),
                ..Default::default()
            },
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
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/scape_crater.png");
    let out = dir.path().join("c.vtz");
    let st = bin()
        .args(["encode", "-q", "--max-error", "10%", "--method", "fis,haar"])
        .arg(&src)
        .arg("-o")
        .arg(&out)
        .status()
        .unwrap();
    assert!(st.success());
    for (name, kind) in [("fis", SectionKind::Fis), ("haar", SectionKind::Haar)] {
        let dec = dir.path().join(format!("{name}.tif"));
        let o = bin()
            .args(["decode", "-q", "--section", name])
            .arg(&out)
            .arg("-o")
            .arg(&dec)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let back = vtz::raster::read_path(&dec, &Default::default()).unwrap();
        let bytes = std::fs::read(&out).unwrap();
        let info = vtz::info(&bytes, Default::default()).unwrap();
        let idx = info.sections.iter().position(|e| e.kind == kind).unwrap();
        let direct = vtz::decode_with(
            &bytes,
            &DecodeOptions {
                section: Some(idx),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(back.data, direct.data, "{name}");
    }
    // `info --stats` reports the FIS and Haar parameters.
    let o = bin()
        .args(["info", "--stats", "--json"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["fis"]["k"].as_u64().unwrap() >= 2, "{j}");
    assert!(j["fis"]["iterations"].as_u64().unwrap() >= 1, "{j}");
    assert!(j["haar"]["levels"].as_u64().unwrap() >= 1, "{j}");
    // A section the file does not have: a one-line usage error.
    let o = bin()
        .args(["decode", "-q", "--section", "sibson"])
        .arg(&out)
        .arg("-o")
        .arg(dir.path().join("x.tif"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no sibson section") && err.lines().count() == 1,
        "{err}"
    );
}

#[test]
fn fis_that_cannot_meet_a_bound_says_so() {
    let r = crater();
    let opts = EncodeOptions {
        method: Method::Fis,
        max_error: Some(ErrorBound::PercentOfRange(0.5)),
        ..Default::default()
    };
    let err = vtz::encode(&r, &opts).unwrap_err();
    assert!(matches!(err, vtz::Error::InvalidArgument { .. }), "{err}");
    assert!(err.to_string().contains("cannot meet"), "{err}");
    // `best` simply leaves FIS out.
    let best = EncodeOptions {
        max_error: Some(ErrorBound::PercentOfRange(0.5)),
        ..Default::default()
    };
    let (_, rep) = vtz::encode_report(&r, &best).unwrap();
    assert_ne!(rep.method, Method::Fis);
}

#[test]
fn fis_reproduces_the_papers_fixed_s_setting_without_a_bound() {
    let r = crater();
    let opts = EncodeOptions {
        method: Method::Fis,
        fis_k: Some(16),
        fis_s: Some(0.02),
        ..Default::default()
    };
    let (bytes, rep) = vtz::encode_report(&r, &opts).unwrap();
    assert_eq!(rep.method, Method::Fis);
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
    let bad = EncodeOptions {
        method: Method::Sibson,
        fis_k: Some(8),
        max_error: Some(ErrorBound::PercentOfRange(5.0)),
        ..Default::default()
    };
    assert!(matches!(
        vtz::encode(&r, &bad),
        Err(vtz::Error::InvalidArgument { .. })
    ));
}
