//! The `vtz` binary: exit codes, one-line errors, atomic and non-clobbering output.

use crate::common;

use common::{corpus, json, stderr, tmp, vtz};
use std::path::{Path, PathBuf};

#[test]
fn lossless_encode_decode_compare() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "crater.vtz");
    let o = vtz(["encode", &corpus("scape_crater.png"), "-o", &out, "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let back = tmp(&d, "crater.tif");
    let o = vtz(["decode", &out, "-o", &back, "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let c = json(&vtz([
        "compare",
        &corpus("scape_crater.png"),
        &back,
        "--json",
    ]));
    assert_eq!(c["identical"], true);
    let c = json(&vtz([
        "compare",
        &corpus("scape_crater.png"),
        &out,
        "--json",
    ]));
    assert_eq!(c["identical"], true);
    assert!(c["bits_per_sample"].as_f64().unwrap() > 0.5);
}

#[test]
fn bounded_encode_meets_percent_bound_and_info_lists_sections() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "kauai.vtz");
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let e = json(&vtz([
        "encode",
        &src,
        "-o",
        &out,
        "--max-error",
        "1%",
        "--method",
        "grid",
        "--json",
    ]));
    assert!(e["max_error_pct"].as_f64().unwrap() <= 1.0);
    let c = json(&vtz(["compare", &src, &out, "--json"]));
    assert!(c["max_error_pct"].as_f64().unwrap() <= 1.0, "{c}");
    assert_eq!(c["lost"], 0);
    assert_eq!(c["invented"], 0);
    let i = json(&vtz(["info", &out, "--json"]));
    assert_eq!(i["width"], 1201);
    assert_eq!(i["sample_type"], "i16");
    assert_eq!(i["nodata"], -32768.0);
    assert_eq!(i["georef"]["epsg"], 4326);
    let kinds: Vec<_> = i["sections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["type"].as_str().unwrap().to_string())
        .collect();
    // Kauai's sea is one flat region of exact zeros: it gets a section of its own.
    assert_eq!(kinds, ["mask", "flat", "grid"]);
    let o = vtz(["info", &out]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("primary"));
}

#[test]
fn existing_output_is_not_overwritten_without_force() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "x.vtz");
    std::fs::write(&out, b"keep me").unwrap();
    let o = vtz(["encode", &corpus("scape_crater.png"), "-o", &out]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--force"));
    assert_eq!(std::fs::read(&out).unwrap(), b"keep me");
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &out,
        "--force",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(std::fs::read(&out).unwrap(), b"keep me");
}

#[test]
fn corrupt_input_gives_one_line_error_and_no_output() {
    let d = tempfile::tempdir().unwrap();
    let good = tmp(&d, "good.vtz");
    assert!(
        vtz([
            "encode",
            &corpus("nasadem_west_bijou_escarpment_landlab.asc"),
            "-o",
            &good,
            "-q"
        ])
        .status
        .success()
    );
    let bytes = std::fs::read(&good).unwrap();
    let bad = tmp(&d, "bad.vtz");
    std::fs::write(&bad, &bytes[..bytes.len() - 3]).unwrap();
    let out = tmp(&d, "out.asc");
    let o = vtz(["decode", &bad, "-o", &out]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("truncated"), "{err}");
    assert!(!Path::new(&out).exists());
    // Nothing else (no temporary file) was left behind.
    let names: Vec<PathBuf> = std::fs::read_dir(d.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

/// A file of 0 to 9 bytes (too short to say its version) decoded to a points output is
/// corrupt input, as `info` says (exit 1, "truncated"), not "a raster file" (a usage error);
/// a sound raster file to a points output stays a usage error (exit 2).
#[test]
fn a_short_file_to_points_is_truncated_not_a_raster() {
    let d = tempfile::tempdir().unwrap();
    let golden = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/golden/v1_kauai_crop_grid.vtz"
    );
    let bytes = std::fs::read(golden).unwrap();
    let out = tmp(&d, "out.xyz");
    for n in 0..10 {
        let p = tmp(&d, &format!("short{n}.vtz"));
        std::fs::write(&p, &bytes[..n]).unwrap();
        let o = vtz(["decode", &p, "-o", &out]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{n} bytes: {err}");
        assert!(err.contains("truncated"), "{n} bytes: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(!Path::new(&out).exists());
    }
    let p = tmp(&d, "junk.vtz");
    std::fs::write(&p, b"hello").unwrap();
    let o = vtz(["decode", &p, "-o", &out]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("not a vtz file"), "{}", stderr(&o));
    let o = vtz(["decode", golden, "-o", &out]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("is a raster file"), "{}", stderr(&o));
}

#[test]
fn usage_errors_exit_2() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "x.vtz");
    assert_eq!(vtz(["encode"]).status.code(), Some(2));
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &out,
        "--max-error",
        "-3",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &out,
        "--format",
        "bmp",
    ]);
    assert_eq!(o.status.code(), Some(2));
    // Output onto the input is refused.
    let src = tmp(&d, "a.asc");
    std::fs::copy(corpus("nasadem_west_bijou_escarpment_landlab.asc"), &src).unwrap();
    let o = vtz(["convert", &src, &src, "--force"]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(
        std::fs::read(&src).unwrap(),
        std::fs::read(corpus("nasadem_west_bijou_escarpment_landlab.asc")).unwrap()
    );
}

#[test]
fn missing_input_is_a_runtime_error() {
    let d = tempfile::tempdir().unwrap();
    let o = vtz(["encode", &tmp(&d, "nope.tif"), "-o", &tmp(&d, "x.vtz")]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).starts_with("vtz: I/O error"), "{}", stderr(&o));
}

#[test]
fn georef_and_nodata_survive_geotiff_vtz_geotiff() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm30m_bigtujunga_utm11.tif");
    let v = tmp(&d, "t.vtz");
    let back = tmp(&d, "t.tif");
    assert!(vtz(["encode", &src, "-o", &v, "-q"]).status.success());
    assert!(vtz(["decode", &v, "-o", &back, "-q"]).status.success());
    let a = vtz::read_path(Path::new(&src), &Default::default()).unwrap();
    let b = vtz::read_path(Path::new(&back), &Default::default()).unwrap();
    assert_eq!(a, b);
    assert!(a.georef.as_ref().unwrap().geokeys.is_some());
    assert_eq!(a.nodata, Some(32767.0));
}

/// A tiled file through the CLI: `--tile`, `info --json` with the index, a `.tif` written
/// band by band that reads back as the decode, `--window`, a corrupt tile named in a one-line
/// error (exit 1) and rescued by `--skip-corrupt`.
#[test]
fn tiled_encode_decode_info_and_a_corrupt_tile() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "crater.vtz");
    let src = corpus("scape_crater.png");
    let o = vtz([
        "encode",
        &src,
        "-o",
        &out,
        "--max-error",
        "1%",
        "--tile",
        "128",
        "--threads",
        "2",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info = json(&vtz(["info", &out, "--json"]));
    assert_eq!(info["version"], 5);
    let t = &info["tiles"];
    let n = t["cols"].as_u64().unwrap() * t["rows"].as_u64().unwrap();
    assert!(n >= 9, "tiles of at most 128 over a raster of ~400²");
    assert_eq!(t["count"].as_u64(), Some(n));
    assert_eq!(t["index"].as_array().unwrap().len() as u64, n);
    let tif = tmp(&d, "back.tif");
    let o = vtz(["decode", &out, "-o", &tif, "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let c = json(&vtz(["compare", &tif, &out, "--json"]));
    assert_eq!(
        c["identical"], true,
        "the band-by-band GeoTIFF is the decode"
    );
    let c = json(&vtz(["compare", &src, &tif, "--json"]));
    assert!(c["max_error_pct"].as_f64().unwrap() <= 1.0 + 1e-9);
    let w = tmp(&d, "win.tif");
    let o = vtz(["decode", &out, "-o", &w, "--window", "90,90,40,40", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Corrupt the middle of tile 5's block.
    let t5 = &info["tiles"]["index"][5];
    // (Version 5: the block is its head at "offset", then its tail at "tail_offset".)
    let (p, head) = (
        t5["bytes"].as_u64().unwrap() / 2,
        t5["head_bytes"].as_u64().unwrap(),
    );
    let at = if p < head {
        t5["offset"].as_u64().unwrap() + p
    } else {
        t5["tail_offset"].as_u64().unwrap() + p - head
    } as usize;
    let mut bytes = std::fs::read(&out).unwrap();
    bytes[at] ^= 0x5a;
    let bad = tmp(&d, "bad.vtz");
    std::fs::write(&bad, &bytes).unwrap();
    let fail = tmp(&d, "fail.tif");
    let o = vtz(["decode", &bad, "-o", &fail]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("tile 5") && e.lines().count() == 1, "{e}");
    assert!(!Path::new(&fail).exists(), "no output on failure");
    let o = vtz(["decode", &bad, "-o", &fail, "--skip-corrupt"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: wrote nodata for tile 5"),
        "{}",
        stderr(&o)
    );
}
