//! What a new user hits (issue 9): one test per item found by trying vtz as a new user, each
//! asserting the behaviour that user should meet.

use crate::common;
use common::*;
use std::path::Path;
use vtz::internals::container;
use vtz::{ErrorBound, Method, Raster, SampleType};

fn code(o: &std::process::Output) -> i32 {
    o.status.code().expect("exit code")
}

/// A 2-section grid file of the corpus Kauai tile within 1 m.
fn kauai_vtz(dir: &tempfile::TempDir) -> String {
    let f = tmp(dir, "k.vtz");
    ok(&vtz([
        "encode",
        &corpus("srtm3_N22W160_kauai.hgt"),
        "-o",
        &f,
        "--max-error",
        "1",
        "--method",
        "grid",
        "-q",
    ]));
    f
}

// 1. `--scale` far beyond the limits: a one-line limit error, exit 1, no output, nothing
//    allocated (tests/suite/limits.rs covers the library side).
#[test]
fn item1_decode_scale_beyond_the_limit_is_refused_before_allocating() {
    let d = tempfile::tempdir().unwrap();
    let f = kauai_vtz(&d);
    for s in ["1000", "50"] {
        let out = tmp(&d, "big.tif");
        let o = vtz(["decode", &f, "-o", &out, "--scale", s]);
        assert_eq!(code(&o), 1, "{}", stderr(&o));
        assert!(stderr(&o).contains("over the limit"), "{}", stderr(&o));
        assert_eq!(stderr(&o).lines().count(), 1);
        assert!(!Path::new(&out).exists());
    }
}

// 2. `best` shortlists by a trial on sample tiles and writes the exhaustive choice's bytes.
#[test]
fn item2_best_chooses_by_estimate_and_writes_the_exhaustive_choice() {
    // 640 × 480 (past the exhaustive size): a noisy terrain at a tight bound, where the
    // grid wins by far and the sites encoder is the slow one.
    let r = terrain(Kind::Fbm, 640, 480, 7, true, SampleType::F32);
    let b = Some(ErrorBound::Abs(0.05));
    let (best, rep) = vtz::encode_report(&r, &encode_opts(&[], b)).unwrap();
    let all = encode_opts(&Method::all().collect::<Vec<_>>(), b);
    let (_, exh) = vtz::encode_report(&r, &all).unwrap();
    assert_eq!(rep.method.name(), exh.method.name());
    let (alone, _) = vtz::encode_report(&r, &encode_opts(&[exh.method], b)).unwrap();
    assert_eq!(best, alone, "best writes the exhaustive winner's file");
    assert!(
        !rep.encoded.contains(&Method::SIBSON),
        "the trial left the sites encoder out: {:?}",
        rep.encoded
    );
    // Small rasters still get every method in full.
    let small = terrain(Kind::Fbm, 100, 80, 7, false, SampleType::F32);
    let (_, rep) = vtz::encode_report(&small, &encode_opts(&[], b)).unwrap();
    assert_eq!(rep.encoded.len(), Method::all().count());
}

// 3. Whole-number float data at a bound below half a unit: lossless is considered.
#[test]
fn item3_best_stores_whole_number_floats_losslessly_below_half_a_unit() {
    let mut r = terrain(Kind::Fbm, 120, 90, 3, true, SampleType::F32);
    for (i, v) in r.data.iter_mut().enumerate() {
        if r.mask.as_ref().is_none_or(|m| m[i]) {
            *v = v.round();
        }
    }
    let (lossless, _) = vtz::encode_report(&r, &encode_opts(&[Method::GRID], None)).unwrap();
    let (best, rep) =
        vtz::encode_report(&r, &encode_opts(&[], Some(ErrorBound::Abs(0.3)))).unwrap();
    assert!(
        best.len() <= lossless.len(),
        "{} > {}",
        best.len(),
        lossless.len()
    );
    assert_eq!(rep.max_error, 0.0);
}

// 4. Progress: from 0, never backwards, to 1, for encode and decode.
#[test]
fn item4_progress_is_monotonic_from_the_start_for_encode_and_decode() {
    let r = terrain(Kind::Fbm, 200, 300, 5, true, SampleType::I16);
    let mut seen = Vec::new();
    let (bytes, _) = vtz::encode_progress(
        &r,
        &encode_opts(&[Method::SIBSON, Method::HAAR], Some(ErrorBound::Abs(3.0))),
        &mut |f| seen.push(f),
    )
    .unwrap();
    assert_eq!(seen.first(), Some(&0.0));
    assert_eq!(seen.last(), Some(&1.0));
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    assert!(seen.len() > 3);
    let seen = std::sync::Mutex::new(Vec::new());
    let mut d = vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec())).unwrap();
    d.section(vtz::SectionChoice::Method(Method::SIBSON));
    let out = d
        .decode_progress(&|f| seen.lock().unwrap().push(f))
        .unwrap();
    assert_eq!(out.width, 200);
    let seen = seen.into_inner().unwrap();
    assert_eq!(seen.first(), Some(&0.0));
    assert_eq!(seen.last(), Some(&1.0));
    // Row chunks of the sites surface report as they finish (300 rows: several).
    assert!(seen.len() >= 5, "{seen:?}");
}

// 5. `--sites` with a bound, `--level` with `--sites`, and out-of-range values: refused.
#[test]
fn item5_sites_and_levels_are_never_silently_overridden_or_clamped() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("scape_crater.png");
    let f = tmp(&d, "s.vtz");
    let o = vtz([
        "encode",
        &src,
        "-o",
        &f,
        "--max-error",
        "1",
        "--sites",
        "100",
    ]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("--sites"), "{}", stderr(&o));
    let mut opts = encode_opts(&[Method::SIBSON], Some(ErrorBound::Abs(1.0)));
    opts.params.sibson.sites = Some(100);
    let r = read_corpus("scape_crater.png");
    assert!(matches!(
        vtz::encode(&r, &opts),
        Err(vtz::Error::InvalidArgument { .. })
    ));
    ok(&vtz(["encode", &src, "-o", &f, "--sites", "300", "-q"]));
    let out = tmp(&d, "o.tif");
    let o = vtz(["decode", &f, "-o", &out, "--sites", "100", "--level", "2"]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    for args in [
        ["--sites", "100000"],
        ["--sites", "3"],
        ["--level", "0"],
        ["--level", "99"],
    ] {
        let o = vtz(["decode", &f, "-o", &out, args[0], args[1]]);
        assert_eq!(code(&o), 2, "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(args[0]), "{}", stderr(&o));
        assert!(!Path::new(&out).exists());
    }
    ok(&vtz(["decode", &f, "-o", &out, "--sites", "300", "-q"]));
}

// 6. No silent data changes in PNG: float rounding needs --round; a colour PNG is heights
//    only when the caller says so.
#[test]
fn item6_png_neither_rounds_nor_reads_colour_as_heights_silently() {
    let d = tempfile::tempdir().unwrap();
    // Delft: float metres with centimetres.
    let src = corpus("ahn3_delft_dsm_50cm.f32");
    let png = tmp(&d, "b.png");
    let o = vtz(["convert", &src, &png, "--png-offset=-10"]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("--round"), "{}", stderr(&o));
    assert!(!Path::new(&png).exists());
    ok(&vtz([
        "convert",
        &src,
        &png,
        "--png-offset=-10",
        "--round",
        "-q",
    ]));
    // A Terrain-RGB PNG without vtz's sidecar is a colour picture until the caller says.
    let trgb = tmp(&d, "t.png");
    let o = vtz([
        "convert",
        &src,
        &trgb,
        "--to",
        "terrain-rgb",
        "--round",
        "-q",
    ]);
    ok(&o);
    let _ = std::fs::remove_file(format!("{trgb}.json"));
    let back = tmp(&d, "t.tif");
    let o = vtz(["convert", &trgb, &back]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--format terrain-rgb"),
        "{}",
        stderr(&o)
    );
    ok(&vtz([
        "convert",
        &trgb,
        &back,
        "--from",
        "terrain-rgb",
        "-q",
    ]));
    // Float64 data into the float32 formats: refused unless --round; a .tif keeps it.
    let r = Raster::from_values(
        3,
        2,
        vec![0.1, 1.0, 2.5, 1e-9, 7.0, 8.0],
        None,
        SampleType::F64,
    )
    .unwrap();
    let f64tif = tmp(&d, "f64.tif");
    vtz::write_path(&r, Path::new(&f64tif), &Default::default()).unwrap();
    for ext in ["exr", "f32"] {
        let out = tmp(&d, &format!("f64.{ext}"));
        let o = vtz(["convert", &f64tif, &out]);
        assert_eq!(code(&o), 2, "{}", stderr(&o));
        assert!(
            stderr(&o).contains("float32") && stderr(&o).contains("--round"),
            "{}",
            stderr(&o)
        );
        ok(&vtz(["convert", &f64tif, &out, "--round", "-q"]));
    }
    let again = tmp(&d, "again.tif");
    ok(&vtz(["convert", &f64tif, &again, "-q"]));
    assert_same(
        &r,
        &vtz::read_path(Path::new(&again), &Default::default()).unwrap(),
        "f64 tif",
    );
}

// 7. One method that cannot meet the bound is left out of a several-method file, with a note.
#[test]
fn item7_a_method_that_cannot_meet_the_bound_is_skipped_with_a_note() {
    let d = tempfile::tempdir().unwrap();
    let f = tmp(&d, "m.vtz");
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &f,
        "--max-error",
        "0.5",
        "--method",
        "sibson,grid,haar,fis",
    ]);
    ok(&o);
    assert!(
        stderr(&o).contains("note: no fis section"),
        "{}",
        stderr(&o)
    );
    let info = json(&vtz(["info", &f, "--json"]));
    let names: Vec<&str> = info["sections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["type"].as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"grid") && !names.contains(&"fis"),
        "{names:?}"
    );
    // FIS alone cannot: exit 1 (not a usage error), numbers without padding.
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &f,
        "--max-error",
        "0.5",
        "--method",
        "fis",
        "--force",
    ]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(!stderr(&o).contains("000000"), "{}", stderr(&o));
}

// 8. `vtz verify` checks what `info` does not: checksums, decodes, stored range and bounds.
#[test]
fn item8_verify_finds_corrupt_sections_that_info_passes() {
    let d = tempfile::tempdir().unwrap();
    let f = kauai_vtz(&d);
    let o = vtz(["verify", &f]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains(": ok"));
    // A flipped payload byte: info passes, verify fails.
    let mut b = std::fs::read(&f).unwrap();
    let n = b.len();
    b[n - 100] ^= 0x10;
    let bad = tmp(&d, "bad.vtz");
    std::fs::write(&bad, &b).unwrap();
    ok(&vtz(["info", &bad, "--stats"]));
    let o = vtz(["verify", &f, &bad, "--json"]);
    assert_eq!(code(&o), 1);
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["ok"], true);
    assert_eq!(lines[1]["ok"], false);
    assert!(lines[1]["error"].as_str().unwrap().contains("checksum"));
    // A header whose value range was narrowed, checksums recomputed: the decode is outside.
    let bytes = std::fs::read(&f).unwrap();
    let c = container::read(&bytes, Default::default()).unwrap();
    let mut h = c.header.clone();
    let (lo, hi) = h.range.unwrap();
    h.range = Some((lo + 100.0, hi));
    let edited = tmp(&d, "edited.vtz");
    std::fs::write(&edited, container::write(&h, &c.sections)).unwrap();
    let o = vtz(["verify", &edited]);
    assert_eq!(code(&o), 1);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("outside the stored range"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}

// 9. Messages and exit codes.
#[test]
fn item9_messages_say_what_is_wrong_and_exit_codes_follow_the_cause() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "o.vtz");
    // A constant raster at 1 % of its (zero) range with sibson: not "needs --max-error".
    let c = Raster::from_values(8, 8, vec![42.0; 64], None, SampleType::I16).unwrap();
    let cf = tmp(&d, "c.tif");
    vtz::write_path(&c, Path::new(&cf), &Default::default()).unwrap();
    for m in ["sibson", "fis"] {
        let o = vtz([
            "encode",
            &cf,
            "-o",
            &out,
            "--method",
            m,
            "--max-error",
            "1%",
        ]);
        assert_eq!(code(&o), 1, "{}", stderr(&o));
        assert!(!stderr(&o).contains("needs --max-error"), "{}", stderr(&o));
        assert!(stderr(&o).contains("--lossless"), "{}", stderr(&o));
    }
    // `best` at the same request stores it (losslessly).
    ok(&vtz(["encode", &cf, "-o", &out, "--max-error", "1%", "-q"]));
    std::fs::remove_file(&out).unwrap();
    for e in ["NaN", "inf", "1e400", "-1"] {
        let o = vtz(["encode", &cf, "-o", &out, &format!("--max-error={e}")]);
        assert_eq!(code(&o), 2);
        assert!(
            stderr(&o).contains("finite number ≥ 0"),
            "{e}: {}",
            stderr(&o)
        );
    }
    let o = vtz(["encode", &cf, "-o", &out, "--rmse", "0"]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("--lossless"), "{}", stderr(&o));
    let f = kauai_vtz(&d);
    let o = vtz(["decode", &f, "-o", &tmp(&d, "x.tif"), "--section", "0"]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("is the mask"), "{}", stderr(&o));
    // Corrupt inputs exit 1: a truncated .vtz, a .tif that is not one.
    let bytes = std::fs::read(&f).unwrap();
    let cut = tmp(&d, "cut.vtz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let o = vtz(["decode", &cut, "-o", &tmp(&d, "y.tif")]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let junk = tmp(&d, "junk.tif");
    std::fs::write(&junk, b"II*\0 this is no tiff").unwrap();
    let o = vtz(["encode", &junk, "-o", &out]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    // Summary numbers carry the digits that matter.
    let o = vtz([
        "encode",
        &corpus("nasadem_west_bijou_escarpment_landlab.asc"),
        "-o",
        &out,
        "--max-error",
        "0.1%",
        "--force",
    ]);
    ok(&o);
    let line = stderr(&o);
    let longest = line
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .map(str::len)
        .max()
        .unwrap();
    assert!(longest <= 12, "{line}");
}

// 10. Failures that can be found before the work are found before it.
#[test]
fn item10_a_missing_output_directory_fails_before_encoding() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "no/such/dir/k.vtz");
    let o = vtz([
        "encode",
        &corpus("srtm3_N22W160_kauai.hgt"),
        "-o",
        &out,
        "--max-error",
        "1",
    ]);
    assert_eq!(code(&o), 1);
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
    assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
    // Options are checked before the input is read: a typo in --method is reported even
    // for an input that does not exist.
    let o = vtz([
        "encode",
        "no-such-input.tif",
        "-o",
        &tmp(&d, "k.vtz"),
        "--method",
        "nope",
    ]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("unknown method"), "{}", stderr(&o));
    // An output whose format cannot be told is refused before the input is read.
    for cmd in ["decode", "convert"] {
        let out = tmp(&d, "out.xyzw");
        let o = if cmd == "decode" {
            vtz([cmd, "no-such-input.vtz", "-o", &out])
        } else {
            vtz([cmd, "no-such-input.tif", &out])
        };
        assert_eq!(code(&o), 2, "{}", stderr(&o));
        assert!(
            stderr(&o).contains("cannot tell the format"),
            "{}",
            stderr(&o)
        );
    }
    let f = kauai_vtz(&d);
    for cmd in [
        vec!["decode", f.as_str(), "-o", out.as_str()],
        vec!["convert", f.as_str(), out.as_str()],
    ] {
        let o = vtz(&cmd);
        assert_eq!(code(&o), 1, "{cmd:?}");
        assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
    }
}

// Found while checking the README's commands: `vtz info F | head -1` panicked on the closed
// pipe. A reader that stops early ends the command quietly; never a panic.
#[test]
fn a_reader_that_stops_early_is_not_a_panic() {
    use std::process::{Command, Stdio};
    let d = tempfile::tempdir().unwrap();
    let f = kauai_vtz(&d);
    let sites = tmp(&d, "s.vtz");
    ok(&vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &sites,
        "--sites",
        "3000",
        "-q",
    ]));
    for args in [
        vec!["info", f.as_str()],
        vec!["info", f.as_str(), "--json"],
        vec!["verify", f.as_str()],
        vec!["sites", sites.as_str()],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_vtz"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take()); // the reader is gone before the first line
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
}
