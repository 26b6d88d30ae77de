//! `vtz rd`: output files, CSV columns and rows, the baseline check, argument errors.
//!
//! Runs on a small synthetic raster with the sibson and grid methods only, so it is fast
//! and independent of the other methods.

use crate::common;

use common::{Kind, stderr, terrain, tmp, vtz};
use std::process::Output;
use vtz::SampleType;

const COLUMNS: &str = "file,method,bound,bound_abs,samples,bytes,bps,ratio,rmse,max_error,\
                       rmse_pct,max_error_pct,enc_s,dec_s,bound_ok,written,sites,note";

/// A 48×40 hill with ridges, as `hill.f32` + `hill.json` in `dir`.
fn hill(dir: &tempfile::TempDir) -> String {
    let (w, h) = (48usize, 40usize);
    let r = terrain(Kind::Hill, w, h, 0, false, SampleType::F32);
    let bytes: Vec<u8> = r
        .data
        .iter()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    std::fs::write(dir.path().join("hill.f32"), bytes).unwrap();
    std::fs::write(
        dir.path().join("hill.json"),
        format!(r#"{{"width": {w}, "height": {h}, "nodata": null}}"#),
    )
    .unwrap();
    tmp(dir, "hill.f32")
}

/// Data rows of a CSV written by `vtz rd` (the first columns hold no commas).
fn rows(csv: &str) -> Vec<Vec<String>> {
    csv.lines()
        .skip(1)
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

#[test]
fn writes_table_csv_markdown_and_plot() {
    let d = tempfile::tempdir().unwrap();
    let src = hill(&d);
    let (csv, md, png) = (tmp(&d, "rd.csv"), tmp(&d, "rd.md"), tmp(&d, "rd.png"));
    let o = vtz([
        "rd",
        &src,
        "--methods",
        "sibson,grid",
        "--bounds",
        "1%,3%,10%",
        "--csv",
        &csv,
        "--md",
        &md,
        "--png",
        &png,
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.starts_with("| raster | method | bound |"), "{out}");
    assert_eq!(out.lines().count(), 2 + 6, "{out}");

    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().next().unwrap(), COLUMNS);
    let rows = rows(&text);
    assert_eq!(rows.len(), 6);
    let mut keys: Vec<(String, String)> =
        rows.iter().map(|r| (r[1].clone(), r[2].clone())).collect();
    keys.sort();
    let mut want: Vec<(String, String)> = ["sibson", "grid"]
        .iter()
        .flat_map(|m| ["1%", "3%", "10%"].map(|b| (m.to_string(), b.to_string())))
        .collect();
    want.sort();
    assert_eq!(keys, want);
    for r in &rows {
        assert_eq!(r[0], "hill.f32");
        assert_eq!(r[4], "1920", "samples");
        let bps: f64 = r[6].parse().unwrap();
        let ratio: f64 = r[7].parse().unwrap();
        assert!(bps > 0.0 && bps < 32.0, "{r:?}");
        assert!(
            (ratio * bps - 32.0).abs() < 0.01 * 32.0,
            "ratio is f32 bits / bps: {r:?}"
        );
        let bound: f64 = r[2].trim_end_matches('%').parse().unwrap();
        let max_pct: f64 = r[11].parse().unwrap();
        assert!(max_pct <= bound, "{r:?}");
        assert_eq!(r[14], "yes", "bound held: {r:?}");
    }

    let md_text = std::fs::read_to_string(&md).unwrap();
    assert_eq!(md_text, out, "--md holds the printed table");
    let png_bytes = std::fs::read(&png).unwrap();
    assert!(png_bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    assert!(png_bytes.len() > 5000, "a plot, not an empty image");

    // Outputs are not replaced without --force (checked before any encoding).
    let o = vtz(["rd", &src, "--methods", "grid", "--csv", &csv, "-q"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--force"), "{}", stderr(&o));
}

#[test]
fn json_rows_and_unavailable_methods() {
    let d = tempfile::tempdir().unwrap();
    let src = hill(&d);
    // Sibson cannot be lossless: its row is "not available", which is not a failure.
    let o = vtz([
        "rd",
        &src,
        "--methods",
        "sibson,grid",
        "--bounds",
        "0",
        "--json",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let rows = j["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0]["method"], "sibson");
    assert!(rows[0]["bps"].is_null());
    assert!(rows[0]["bound_ok"].is_null());
    assert!(
        rows[0]["note"]
            .as_str()
            .unwrap()
            .starts_with("not available:"),
        "{}",
        rows[0]
    );
    assert_eq!(rows[1]["method"], "grid");
    assert_eq!(rows[1]["max_error"], 0.0);
    assert_eq!(rows[1]["bound_ok"], true);
    assert!(j["baseline"].is_null());
}

#[test]
fn baseline_passes_against_itself_and_fails_on_growth() {
    let d = tempfile::tempdir().unwrap();
    let src = hill(&d);
    let base = tmp(&d, "base.csv");
    let args = |extra: &[&str]| -> Output {
        let mut a = vec!["rd", &src, "--methods", "sibson,grid", "--bounds", "1%,10%"];
        a.extend_from_slice(extra);
        vtz(&a)
    };
    let o = args(&["--csv", &base, "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));

    let o = args(&["--baseline", &base]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("0 regressions"),
        "summary line: {}",
        stderr(&o)
    );

    // Lower one row's baseline bps: by 1 % it is within the 2 % tolerance, by 3 % it fails.
    let text = std::fs::read_to_string(&base).unwrap();
    let edit = |factor: f64, name: &str| -> String {
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let i = 1 + rows(&text)
            .iter()
            .position(|r| r[1] == "sibson" && r[2] == "10%")
            .unwrap();
        let mut f: Vec<String> = lines[i].split(',').map(str::to_string).collect();
        let bps: f64 = f[6].parse().unwrap();
        f[6] = format!("{:.6}", bps * factor);
        lines[i] = f.join(",");
        let p = tmp(&d, name);
        std::fs::write(&p, lines.join("\n") + "\n").unwrap();
        p
    };
    let within = edit(0.99, "within.csv");
    let o = args(&["--baseline", &within]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("within tolerance"), "{}", stderr(&o));

    let worse = edit(0.97, "worse.csv");
    let o = args(&["--baseline", &worse, "-q"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    let regressions: Vec<&str> = err.lines().filter(|l| l.contains("regression:")).collect();
    assert_eq!(regressions.len(), 1, "{err}");
    assert!(regressions[0].contains("hill.f32 sibson 10%"), "{err}");
    // A looser tolerance accepts it.
    let o = args(&["--baseline", &worse, "--tolerance", "5", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));

    // Raising the baseline is reported as an improvement, not a failure.
    let better = edit(1.5, "better.csv");
    let o = args(&["--baseline", &better]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("improvement: hill.f32 sibson 10%"),
        "{}",
        stderr(&o)
    );

    // Rows missing on either side are reported but do not fail.
    let o = vtz([
        "rd",
        &src,
        "--methods",
        "grid",
        "--bounds",
        "1%,3%",
        "--baseline",
        &base,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("hill.f32 grid 3%: not in the baseline"),
        "{err}"
    );
    assert!(
        err.contains("hill.f32 sibson 1%: in the baseline, not run"),
        "{err}"
    );
}

#[test]
fn bad_arguments_are_one_line_errors_with_exit_code_2() {
    let d = tempfile::tempdir().unwrap();
    let src = hill(&d);
    for args in [
        vec!["rd", &src, "--bounds", "1%,abc"],
        vec!["rd", &src, "--bounds", "-1%"],
        vec!["rd", &src, "--bounds", ","],
        vec!["rd", &src, "--methods", "sibson,zip"],
        vec!["rd", &src, "--baseline", "x.csv", "--tolerance", "-1"],
    ] {
        let o = vtz(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("vtz: invalid argument"), "{args:?}: {err}");
        assert!(o.stdout.is_empty(), "{args:?}");
    }
    // A baseline without the needed columns fails before any encoding.
    let bad = tmp(&d, "bad.csv");
    std::fs::write(&bad, "file,method\nhill.f32,grid\n").unwrap();
    let o = vtz(["rd", &src, "--methods", "grid", "--baseline", &bad]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no 'bound' column"), "{}", stderr(&o));
}
