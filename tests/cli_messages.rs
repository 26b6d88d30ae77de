//! What a user reads: error messages that name a file once, exit codes by cause, outputs
//! checked before the work, temporaries never left behind, `info` showing the bound.

mod common;

use common::{corpus, json, stderr, tmp, vtz};

/// A message names its file once (`nosuch.tif: No such file…`, not `nosuch.tif: nosuch.tif:`).
#[test]
fn missing_inputs_are_named_once() {
    let d = tempfile::tempdir().unwrap();
    for name in ["nosuch.tif", "nosuch.laz", "nosuch.xyz", "nosuch.hgt"] {
        let input = tmp(&d, name);
        let o = vtz(["encode", &input, "-o", &tmp(&d, "x.vtz")]);
        assert_eq!(o.status.code(), Some(1), "{name}: {}", stderr(&o));
        let e = stderr(&o);
        assert_eq!(e.matches(name).count(), 1, "{name}: {e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}

/// A bad value in a text point file is corrupt input: exit 1, as the README says.
#[test]
fn a_bad_xyz_value_is_corrupt_input() {
    let d = tempfile::tempdir().unwrap();
    let input = tmp(&d, "bad.xyz");
    std::fs::write(&input, "1 2 3\n4 5 abc\n").unwrap();
    let o = vtz([
        "encode",
        &input,
        "-o",
        &tmp(&d, "x.vtz"),
        "--max-error",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("line 2") && e.contains("abc"), "{e}");
    assert_eq!(e.matches("bad.xyz").count(), 1, "{e}");
}

/// An output below a path that is a file: "is not a directory", not "does not exist".
#[test]
fn an_output_below_a_file_says_not_a_directory() {
    let d = tempfile::tempdir().unwrap();
    let file = tmp(&d, "one.tif");
    std::fs::write(&file, b"x").unwrap();
    let out = format!("{file}/x.vtz");
    let o = vtz(["encode", &corpus("scape_crater.png"), "-o", &out]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("is not a directory"), "{e}");
    assert!(!e.contains("does not exist"), "{e}");
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &tmp(&d, "no/x.vtz"),
    ]);
    assert!(stderr(&o).contains("does not exist"), "{}", stderr(&o));
}

/// `vtz tiles` checks its output directory's parent before reading or tiling anything,
/// and blames the output, not the input.
#[test]
fn tiles_check_the_output_directory_first() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let o = vtz(["tiles", &src, "-o", &format!("{}/", tmp(&d, "nodir/sub"))]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("nodir") && e.contains("does not exist"), "{e}");
    assert!(!e.contains("kauai"), "the input is not to blame: {e}");
    // An existing directory that is not a pyramid: refused before the work, even with --force.
    let dir = tmp(&d, "keep");
    std::fs::create_dir(&dir).unwrap();
    let o = vtz(["tiles", &src, "-o", &dir]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--force"), "{}", stderr(&o));
    let o = vtz(["tiles", &src, "-o", &dir, "--force"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("layer.json"), "{}", stderr(&o));
}

/// An ESRI ASCII grid of `w × h` samples, all `v` except `holes` set to nodata.
fn asc(path: &str, w: usize, h: usize, v: i32, holes: &[(usize, usize)]) {
    let mut s = format!(
        "ncols {w}\nnrows {h}\nxllcorner 10\nyllcorner 45\ncellsize 0.001\nNODATA_value -9999\n"
    );
    for r in 0..h {
        let row: Vec<String> = (0..w)
            .map(|c| if holes.contains(&(c, r)) { -9999 } else { v }.to_string())
            .collect();
        s.push_str(&row.join(" "));
        s.push('\n');
    }
    std::fs::write(path, s).unwrap();
}

/// A constant raster, or a 1 × 1 one, meshes as a flat rectangle of two triangles, with
/// or without a bound, and `vtz tiles` of a constant geographic raster blames no bound.
#[test]
fn constant_and_single_sample_rasters_mesh_flat() {
    let d = tempfile::tempdir().unwrap();
    for (name, w, h, holes) in [
        ("const.asc", 50, 40, vec![]),
        ("holes.asc", 50, 40, vec![(0, 0), (10, 10)]),
        ("one.asc", 1, 1, vec![]),
        ("row.asc", 7, 1, vec![]),
    ] {
        let src = tmp(&d, name);
        asc(&src, w, h, 7, &holes);
        for bound in [None, Some("1"), Some("1%")] {
            let out = tmp(&d, "m.obj");
            let mut args = vec!["mesh", &src, "-o", &out, "--force", "--json"];
            if let Some(b) = bound {
                args.extend(["--max-error", b]);
            }
            let j = json(&vtz(args));
            assert_eq!(j["triangles"], 2, "{name} {bound:?}: {j}");
            assert_eq!(j["vertices"], 4, "{name} {bound:?}: {j}");
            assert!(j["max_error"].as_f64().unwrap() < 1e-9, "{name}: {j}");
            let obj = std::fs::read_to_string(&out).unwrap();
            let zs: Vec<f64> = obj
                .lines()
                .filter_map(|l| l.strip_prefix("v "))
                .map(|l| l.split(' ').nth(2).unwrap().parse().unwrap())
                .collect();
            assert_eq!(zs, [7.0; 4], "{name}");
        }
    }
    // A constant SRTM tile: a pyramid, not "--max-error 0 is finer than a height step".
    let hgt = tmp(&d, "N45E010.hgt");
    std::fs::write(&hgt, 7i16.to_be_bytes().repeat(1201 * 1201)).unwrap();
    let o = vtz(["tiles", &hgt, "-o", &tmp(&d, "t"), "-q", "--max-zoom", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::path::Path::new(&tmp(&d, "t/layer.json")).is_file());
}

/// `info` shows the stored bound (and each method section's) without `--stats`.
#[test]
fn info_shows_the_bound() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let out = tmp(&d, "k.vtz");
    let e = json(&vtz([
        "encode",
        &src,
        "-o",
        &out,
        "--max-error",
        "2",
        "--json",
    ]));
    let bound = e["max_error"].as_f64().unwrap();
    assert!(bound > 0.0 && bound <= 2.0, "{e}");
    let i = json(&vtz(["info", &out, "--json"]));
    assert_eq!(i["max_error"].as_f64(), Some(bound), "{i}");
    assert_eq!(i["lossless"], false);
    let primary = i["sections"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["primary"] == true)
        .unwrap();
    assert_eq!(primary["max_error"].as_f64(), Some(bound));
    assert_eq!(primary["type"], e["method"]);
    let mask = &i["sections"][0];
    assert_eq!(mask["type"], "mask");
    assert!(mask["max_error"].is_null());
    let o = vtz(["info", &out]);
    let text = String::from_utf8_lossy(&o.stdout);
    let line = text.lines().find(|l| l.starts_with("max error")).unwrap();
    assert!(line.contains(&vtz::metrics::num(bound)), "{text}");
    // Lossless says so.
    let out = tmp(&d, "l.vtz");
    assert!(vtz(["encode", &src, "-o", &out, "-q"]).status.success());
    let i = json(&vtz(["info", &out, "--json"]));
    assert_eq!(i["max_error"].as_f64(), Some(0.0));
    assert_eq!(i["lossless"], true);
    let text = String::from_utf8_lossy(&vtz(["info", &out]).stdout).to_string();
    assert!(text.contains("max error     0 (lossless)"), "{text}");
}

/// A 1 × 1 raster stored losslessly is told why the file outweighs it (the framing), not
/// to try `--lossless`.
#[test]
fn tiny_rasters_are_not_told_to_try_lossless() {
    let d = tempfile::tempdir().unwrap();
    let src = tmp(&d, "one.asc");
    asc(&src, 1, 1, 5, &[]);
    for args in [vec![], vec!["--max-error", "1"]] {
        let mut a = vec!["encode", &src, "-o", "", "--force"];
        let out = tmp(&d, "one.vtz");
        a[3] = &out;
        a.extend(args.iter().copied());
        let o = vtz(&a);
        assert!(o.status.success(), "{}", stderr(&o));
        let e = stderr(&o);
        assert!(!e.contains("--lossless"), "{e}");
        assert!(
            e.contains("header, directory and checksums outweigh"),
            "{e}"
        );
    }
}

/// `vtz sites` prints the shortest decimal of a lattice height, not its binary rounding
/// (`2210.229`, not `2210.2290000000003`), and the values read back within 1e-12.
#[test]
fn sites_print_short_decimals() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "c.vtz");
    let o = vtz([
        "encode",
        &corpus("scape_crater.png"),
        "-o",
        &out,
        "--method",
        "sibson",
        "--max-error",
        "0.3%",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = vtz(["sites", &out]);
    let csv = String::from_utf8_lossy(&o.stdout).to_string();
    let heights: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap())
        .collect();
    assert!(heights.len() > 100);
    for h in &heights {
        let digits = h.chars().filter(char::is_ascii_digit).count();
        assert!(digits <= 15, "{h}");
    }
    // The library's sites, formatted the same way, are what the CSV holds.
    let bytes = std::fs::read(&out).unwrap();
    let mut dec = vtz::Decoder::new(std::io::Cursor::new(bytes)).unwrap();
    let sites = dec.sites().unwrap();
    assert_eq!(sites.len(), heights.len());
    for (s, h) in sites.iter().zip(&heights) {
        let back: f64 = h.parse().unwrap();
        assert!(
            (back - s.height).abs() <= 1e-12 * s.height.abs().max(1.0),
            "{h}"
        );
    }
}

/// The progress of a `best` encode is weighted by each stage's cost: it starts at 0, never
/// falls, moves in steps of less than half the bar, and ends at 1 (Kauai at 1 m: the trial
/// on sample tiles, then the residual layer, which now reports each coding pass).
#[test]
fn best_progress_moves_evenly_to_the_end() {
    let r = common::read_corpus("srtm3_N22W160_kauai.hgt");
    for bound in [
        vtz::ErrorBound::Abs(1.0),
        vtz::ErrorBound::PercentOfRange(1.0),
    ] {
        let mut seen: Vec<f64> = Vec::new();
        let opts = common::encode_opts(&[], Some(bound));
        vtz::encode_progress(&r, &opts, &mut |f| seen.push(f)).unwrap();
        assert_eq!(seen.first(), Some(&0.0));
        assert_eq!(seen.last(), Some(&1.0));
        assert!(seen.windows(2).all(|w| w[1] >= w[0]), "{seen:?}");
        let gap = seen.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
        assert!(gap < 0.5, "{bound:?}: a jump of {gap} in {seen:?}");
        assert!(seen.len() >= 6, "{seen:?}");
    }
}

/// Ctrl-C (SIGINT) during an encode removes the hidden temporary and writes no output;
/// the command stops with 130.
#[cfg(unix)]
#[test]
fn interrupted_encode_leaves_nothing() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "istria.vtz");
    let child = Command::new(env!("CARGO_BIN_EXE_vtz"))
        .args([
            "encode",
            &corpus("srtm1_N45E013_istria_crop2400.png"),
            "-o",
            &out,
            "--max-error",
            "1",
            "--effort",
            "9",
            "--threads",
            "1",
        ])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let entries = || -> Vec<String> {
        std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    };
    let t0 = Instant::now();
    while !entries().iter().any(|n| n.contains("vtz-tmp")) {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no temporary appeared"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(200));
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stderr(&o).contains("interrupted"), "{}", stderr(&o));
    assert_eq!(entries(), Vec::<String>::new(), "left behind");
}

/// The README's Python commands create `.venv/` in the checkout: git ignores it, so a new
/// user's `git status` stays clean.
#[test]
fn the_readme_venv_is_ignored() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(
        readme.contains("python3 -m venv .venv"),
        "the README no longer makes .venv"
    );
    let ignore = std::fs::read_to_string(root.join(".gitignore")).unwrap();
    assert!(
        ignore
            .lines()
            .any(|l| matches!(l.trim(), ".venv/" | ".venv" | "/.venv/" | "/.venv")),
        ".gitignore does not ignore .venv/"
    );
}
