//! Data and sizes that went wrong silently (issue 25, items 7 and 10–15): each test asserts
//! what a user should meet instead.

use crate::common;
use common::*;
use std::path::Path;
use vtz::{ErrorBound, Method, Raster, SampleType, ValueMapping};

fn code(o: &std::process::Output) -> i32 {
    o.status.code().expect("exit code")
}

// 7. A `.f32` written from a 16-bit PNG (metres in the file, `u16` and the PNG's mapping in
//    the sidecar) encodes lossily at the size of the PNG's own encode, not losslessly at
//    nine times it.
#[test]
fn item7_f32_from_a_mapped_png_encodes_lossily() {
    let d = tempfile::tempdir().unwrap();
    let hgt = corpus("srtm3_N22W160_kauai.hgt");
    let png = tmp(&d, "k.png");
    ok(&vtz([
        "convert",
        &hgt,
        &png,
        "--png-offset",
        "-32768",
        "-q",
    ]));
    let f32 = tmp(&d, "k.f32");
    ok(&vtz(["convert", &png, &f32, "-q"]));
    let side: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp(&d, "k.json")).unwrap()).unwrap();
    assert_eq!(side["value_mapping"]["offset"], -32768.0, "{side}");
    let enc = |src: &str, out: &str| {
        json(&vtz([
            "encode",
            src,
            "-o",
            &tmp(&d, out),
            "--max-error",
            "1%",
            "--json",
        ]))
    };
    let direct = enc(&png, "png.vtz");
    let via = enc(&f32, "f32.vtz");
    assert_eq!(via["lossless"], false, "{via}");
    let (a, b) = (
        direct["bytes"].as_u64().unwrap(),
        via["bytes"].as_u64().unwrap(),
    );
    assert!(b * 2 <= a * 3, "{b} bytes from the .f32, {a} from the PNG");
    // The PNG's mapping is still known: the .f32 converts back to the same PNG.
    let back = tmp(&d, "back.png");
    ok(&vtz(["convert", &f32, &back, "-q"]));
    assert_eq!(std::fs::read(&back).unwrap(), std::fs::read(&png).unwrap());
}

// 7. `best` never answers a lossy request with a lossless file without saying why.
#[test]
fn item7_best_says_why_a_lossy_request_got_a_lossless_file() {
    // An i16 raster whose mapping (-32768 + code) its values overflow: no lossy method can
    // code it, so the grid stores the values exactly.
    let mut r = terrain(Kind::Fbm, 100, 80, 7, false, SampleType::I16);
    r.mapping = ValueMapping {
        scale: 1.0,
        offset: -32768.0,
    };
    // (Issue 35, item 15: such values are not values of the raster's type, and the grid
    // stored them as f64 bit keys, which a decoder of an integer file now rejects: the
    // encoder refuses the raster up front, naming the sample and the type.)
    let e = vtz::encode_report(&r, &encode_opts(&[], Some(ErrorBound::PercentOfRange(1.0))))
        .expect_err("values beyond the codes' range");
    let msg = e.to_string();
    assert!(
        matches!(e, vtz::Error::InvalidArgument { .. })
            && msg.contains("sample 0 (row 0, column 0)")
            && msg.contains("is not a value of i16 codes mapped by")
            && !msg.contains('\n'),
        "{msg}"
    );
    // f32 values spread over ten decades with a max error of 1e-30: no lossy method reaches
    // it (the residual layer finds no lattice, Haar's and the sites' steps cannot be that
    // fine), so the grid stores the values exactly, and the report says why.
    let mut x = 7u64;
    let values: Vec<f64> = (0..40 * 30)
        .map(|_| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let (a, b) = (
                (x >> 11) as f64 / (1u64 << 53) as f64,
                (x >> 40) as f64 / (1u64 << 24) as f64,
            );
            ((a * 2.0 - 1.0) * 10f64.powf(b * 10.0 - 5.0)) as f32 as f64
        })
        .collect();
    let r = Raster::from_values(40, 30, values, None, SampleType::F32).unwrap();
    let (bytes, rep) =
        vtz::encode_report(&r, &encode_opts(&[], Some(ErrorBound::Abs(1e-30)))).unwrap();
    assert_eq!(rep.max_error, 0.0);
    assert_eq!(rep.notes.len(), 1, "{:?}", rep.notes);
    assert!(
        rep.notes[0].contains("losslessly") && rep.notes[0].contains("residual"),
        "{}",
        rep.notes[0]
    );
    assert_same(&r, &vtz::decode(&bytes).unwrap(), "stored losslessly");
    // A lossy answer, or a lossless request, has nothing to say.
    let r = terrain(Kind::Fbm, 100, 80, 7, false, SampleType::I16);
    let (_, rep) =
        vtz::encode_report(&r, &encode_opts(&[], Some(ErrorBound::PercentOfRange(1.0)))).unwrap();
    assert!(
        rep.max_error > 0.0 && rep.notes.is_empty(),
        "{:?}",
        rep.notes
    );
    let (_, rep) = vtz::encode_report(&r, &encode_opts(&[], None)).unwrap();
    assert!(rep.notes.is_empty(), "{:?}", rep.notes);
}

// 14. A bound below half the data's step is a lossless request: `best` encodes only the
//     lossless methods (no trial of the others) and writes `--lossless`'s bytes.
#[test]
fn item14_a_bound_below_half_the_step_encodes_losslessly_at_once() {
    let ints = terrain(Kind::Fbm, 120, 90, 3, true, SampleType::I16);
    let mut whole = terrain(Kind::Fbm, 120, 90, 4, true, SampleType::F32);
    for i in 0..whole.len() {
        if whole.is_valid(i) {
            whole.data[i] = whole.data[i].round();
        }
    }
    for r in [ints, whole] {
        let (lossless, _) = vtz::encode_report(&r, &encode_opts(&[], None)).unwrap();
        for b in [0.0, 0.2, 0.4999] {
            let (bytes, rep) =
                vtz::encode_report(&r, &encode_opts(&[], Some(ErrorBound::Abs(b)))).unwrap();
            assert_eq!(rep.max_error, 0.0);
            assert!(
                rep.encoded
                    .iter()
                    .all(|m| *m == Method::GRID || *m == Method::RESIDUAL),
                "bound {b}: {:?} tried",
                rep.encoded
            );
            assert_eq!(bytes, lossless, "bound {b}");
        }
    }
}

// 15. `encode -o NAME.tif` (or any other format's extension) is refused before the work: a
//     usage error, exit 2, nothing written.
#[test]
fn item15_encode_refuses_an_output_named_as_another_format() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    for name in [
        "out.tif", "out.TIFF", "out.png", "out.hgt", "out.f32", "out.laz", "out.xyz",
    ] {
        let out = tmp(&d, name);
        let o = vtz(["encode", &src, "-o", &out, "--max-error", "1"]);
        assert_eq!(code(&o), 2, "{name}: {}", stderr(&o));
        assert!(stderr(&o).contains(".vtz"), "{name}: {}", stderr(&o));
        assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
        assert!(!Path::new(&out).exists(), "{name} written");
    }
    // A .vtz, or a name of no known format, is fine.
    for name in ["out.vtz", "out.bin"] {
        ok(&vtz([
            "encode",
            &src,
            "-o",
            &tmp(&d, name),
            "--max-error",
            "1",
            "-q",
        ]));
    }
}

/// A LAS file of point format 1 (GPS time): 30 points of class 1 and 70 of class 2.
fn classified_las(path: &str) {
    let mut b = las::Builder::from((1, 2));
    b.point_format = las::point::Format::new(1).unwrap();
    b.transforms = las::Vector {
        x: las::Transform {
            scale: 0.01,
            offset: 0.0,
        },
        y: las::Transform {
            scale: 0.01,
            offset: 0.0,
        },
        z: las::Transform {
            scale: 0.01,
            offset: 0.0,
        },
    };
    let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
    for i in 0..100u32 {
        let (x, y) = ((i % 10) as f64, (i / 10) as f64);
        w.write_point(las::Point {
            x,
            y,
            z: 10.0 + (x * 0.7).sin() + y * 0.3,
            classification: las::point::Classification::new(if i < 30 { 1 } else { 2 }).unwrap(),
            gps_time: Some(i as f64),
            return_number: 1,
            number_of_returns: 1,
            ..Default::default()
        })
        .unwrap();
    }
    w.close().unwrap();
}

// 13. A class filter that keeps no point: exit 1 naming the classes present, no file.
#[test]
fn item13_a_class_with_no_points_is_an_error_naming_the_classes() {
    let d = tempfile::tempdir().unwrap();
    let src = tmp(&d, "c.las");
    classified_las(&src);
    let out = tmp(&d, "c.vtz");
    let o = vtz(["encode", &src, "-o", &out, "--class", "99"]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("no points of class 99") && e.contains("classes present: 1, 2"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(!Path::new(&out).exists());
    // A class that is there still encodes.
    ok(&vtz(["encode", &src, "-o", &out, "--class", "2", "-q"]));
}

// 12. LAS → .vtz keeps x, y and z: the encode says what it leaves out (classification,
//     GPS time), so a LAZ decoded from it (format 0, class 0) is no surprise.
#[test]
fn item12_las_attributes_left_out_are_named() {
    let d = tempfile::tempdir().unwrap();
    let src = tmp(&d, "c.las");
    classified_las(&src);
    let out = tmp(&d, "c.vtz");
    let o = vtz(["encode", &src, "-o", &out, "--max-error", "0.1"]);
    ok(&o);
    let e = stderr(&o);
    let note = e
        .lines()
        .find(|l| l.starts_with("note:") && l.contains("classification"))
        .unwrap_or_else(|| panic!("no note on the classification: {e}"));
    assert!(
        note.contains("classes 1, 2") && note.contains("GPS time") && note.contains("format 1"),
        "{note}"
    );
    let o = vtz(["encode", &src, "-o", &tmp(&d, "g.vtz"), "--class", "2"]);
    ok(&o);
    assert!(
        stderr(&o).contains("classification (class 2)"),
        "{}",
        stderr(&o)
    );
    // Text has nothing more than x, y, z: no note.
    let xyz = tmp(&d, "p.xyz");
    std::fs::write(&xyz, "0 0 1\n1 0 2\n0 1 3\n1 1 4\n").unwrap();
    let o = vtz([
        "encode",
        &xyz,
        "-o",
        &tmp(&d, "p.vtz"),
        "--max-error",
        "0.1",
    ]);
    ok(&o);
    assert!(!stderr(&o).contains("keeps x, y and z"), "{}", stderr(&o));
}

// 11. `.hgt` output is placed by its name alone: a name that does not place the raster is
//     refused (exit 2, naming the tile's name), the tile's own name keeps it where it was.
#[test]
fn item11_hgt_output_keeps_its_place_or_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let f = tmp(&d, "k.vtz");
    ok(&vtz(["encode", &src, "-o", &f, "--lossless", "-q"]));
    for out in ["out.hgt", "N23W160.hgt"] {
        let out = tmp(&d, out);
        let o = vtz(["decode", &f, "-o", &out]);
        assert_eq!(code(&o), 2, "{}", stderr(&o));
        assert!(stderr(&o).contains("N22W160"), "{}", stderr(&o));
        assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
        assert!(!Path::new(&out).exists());
    }
    // Under its own name the tile reads back where it was.
    let named = tmp(&d, "N22W160.hgt");
    ok(&vtz(["decode", &f, "-o", &named, "-q"]));
    let a = json(&vtz(["info", &f, "--json"]));
    let back = tmp(&d, "back.vtz");
    ok(&vtz(["encode", &named, "-o", &back, "--lossless", "-q"]));
    let b = json(&vtz(["info", &back, "--json"]));
    assert_eq!(a["georef"], b["georef"]);
    // A window is no tile: refused whatever its name, unless the georef is dropped.
    let o = vtz(["decode", &f, "-o", &named, "-f", "--window", "0,0,100,100"]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    ok(&vtz([
        "decode",
        &f,
        "-o",
        &tmp(&d, "w.hgt"),
        "--window",
        "0,0,100,100",
        "--drop-georef",
        "-q",
    ]));
    // So does convert.
    let o = vtz(["convert", &src, &tmp(&d, "c.hgt")]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
}

// 10. NaN samples of a float raster whose nodata is −9999 are nodata (as GDAL treats NaN):
//     they decode as −9999, every other sample within the bound. Python's `vtz.encode`
//     applies the same rule (python/tests/test_api.py), no longer refusing the array.
#[test]
fn item10_nan_samples_are_nodata_whatever_the_nodata_value() {
    let d = tempfile::tempdir().unwrap();
    let vals: Vec<f32> = (0..64)
        .map(|i| 100.0 + (i as f32 * 0.37).sin() * 20.0)
        .collect();
    let mut with_nan = vals.clone();
    with_nan[5] = f32::NAN;
    with_nan[9] = -9999.0;
    let src = tmp(&d, "n.f32");
    std::fs::write(
        &src,
        with_nan
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<_>>(),
    )
    .unwrap();
    std::fs::write(
        tmp(&d, "n.json"),
        r#"{"width": 8, "height": 8, "source_dtype": "float32", "nodata": -9999}"#,
    )
    .unwrap();
    let f = tmp(&d, "n.vtz");
    ok(&vtz(["encode", &src, "-o", &f, "--max-error", "0.5", "-q"]));
    let back = tmp(&d, "back.f32");
    ok(&vtz(["decode", &f, "-o", &back, "-q"]));
    let got: Vec<f32> = std::fs::read(&back)
        .unwrap()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    for (i, (&g, &v)) in got.iter().zip(&vals).enumerate() {
        if i == 5 || i == 9 {
            assert_eq!(g, -9999.0, "sample {i}");
        } else {
            assert!((g - v).abs() <= 0.5, "sample {i}: {g} vs {v}");
        }
    }
}
