//! What a user reads: error messages that name a file once, exit codes by cause, outputs
//! checked before the work, temporaries never left behind, `info` showing the bound.

use crate::common;

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

/// Every progress report of a run, checked: it starts at 0, never falls, ends at 1, and
/// has at least `moves` values strictly between (the bar moves while the work runs).
fn check_progress(what: &str, seen: &[f64], moves: usize) {
    assert_eq!(seen.first(), Some(&0.0), "{what}: {seen:?}");
    assert_eq!(seen.last(), Some(&1.0), "{what}: {seen:?}");
    assert!(
        seen.windows(2).all(|w| w[1] >= w[0]),
        "{what}: falls: {seen:?}"
    );
    let inner = seen.iter().filter(|&&f| f > 0.0 && f < 1.0).count();
    assert!(
        inner >= moves,
        "{what}: {inner} reports between 0 and 1, want {moves}: {seen:?}"
    );
}

/// An untiled decode reports the end of its method's decode before the end of the whole
/// (it sat at 0 % until the end); with a scale, the resampling reports its rows as they are
/// done (it reported nothing), on one thread and on several.
#[test]
fn untiled_decode_progress_moves_to_the_end() {
    use std::sync::Mutex;
    let src = common::terrain(common::Kind::Fbm, 300, 200, 7, true, vtz::SampleType::I16);
    for m in [vtz::Method::RESIDUAL, vtz::Method::GRID] {
        let bytes = vtz::encode(
            &src,
            &common::encode_opts(&[m], Some(vtz::ErrorBound::Abs(1.0))),
        )
        .unwrap();
        for threads in [1, 2] {
            for scale in [None, Some("2"), Some("1/3")] {
                let seen = Mutex::new(Vec::new());
                let mut d = vtz::Decoder::new(std::io::Cursor::new(bytes.to_vec())).unwrap();
                let opts = common::decode_opts(|o| {
                    o.threads = threads;
                    o.scale = scale.map(|s| s.parse().unwrap());
                });
                let r = d
                    .options(opts)
                    .decode_progress(&|f| seen.lock().unwrap().push(f))
                    .unwrap();
                let seen = seen.into_inner().unwrap();
                let what = format!("{m} threads {threads} scale {scale:?}");
                // The method's end; with a scale also one report per resampled row (a
                // small output: every row).
                let moves = if scale.is_some() { r.height / 2 } else { 1 };
                check_progress(&what, &seen, moves);
            }
        }
    }
}

/// A tiled encode reports each tile's encode as the tile finishes (before it is written:
/// the first report above 0 comes while the output holds no tile yet) and each tile's
/// write, then the end: 2 × tiles + 1 steps, on one thread and on two (it reported each
/// group of 8 or 16 tiles only once the whole group was done and written).
#[test]
fn tiled_encode_progress_reports_each_tile() {
    use std::cell::RefCell;
    use std::io::{Cursor, Seek, SeekFrom, Write};
    use std::rc::Rc;
    /// A file in memory whose length the test reads while the encoder writes it.
    struct Shared(Rc<RefCell<Cursor<Vec<u8>>>>);
    impl Write for Shared {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.borrow_mut().write(b)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    impl Seek for Shared {
        fn seek(&mut self, p: SeekFrom) -> std::io::Result<u64> {
            self.0.borrow_mut().seek(p)
        }
    }
    let mut src = common::terrain(common::Kind::Fbm, 256, 256, 3, false, vtz::SampleType::I16);
    for threads in [1, 2] {
        let mut opts = common::encode_opts(&[], Some(vtz::ErrorBound::Abs(1.0)));
        opts.tile = Some(64);
        opts.threads = threads;
        let file = Rc::new(RefCell::new(Cursor::new(Vec::new())));
        let mut seen: Vec<(f64, usize)> = Vec::new();
        vtz::encode_stream(&mut src, &opts, Shared(file.clone()), &mut |f| {
            seen.push((f, file.borrow().get_ref().len()))
        })
        .unwrap();
        let fractions: Vec<f64> = seen.iter().map(|s| s.0).collect();
        let what = format!("threads {threads}");
        check_progress(&what, &fractions, 2 * 16);
        let header = seen[0].1;
        let first = seen.iter().find(|s| s.0 > 0.0).unwrap();
        assert_eq!(
            first.1, header,
            "{what}: the first tile's encode was reported only after a tile was written: {seen:?}"
        );
        let bytes = file.borrow().get_ref().clone();
        let info = vtz::info(&bytes, Default::default()).unwrap();
        assert_eq!(info.tiles.unwrap().tiles.len(), 16, "{what}");
    }
}

/// Every clap usage error is one line on stderr, exit 2, ending with where the help is;
/// a negative number is taken as an option's value and then checked ("must be ≥ 0").
#[test]
fn usage_errors_are_one_line() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("scape_crater.png");
    let out = tmp(&d, "x.vtz");
    let y = tmp(&d, "y.tif");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["encode", &src, "-o", &out, "--max-error", "1", "--lossless"],
            "cannot be used with",
        ),
        (
            vec!["encode", &src, "-o", &out, "--effort", "0"],
            "0 is not in 1..=9",
        ),
        (
            vec!["encode", &src, "-o", &out, "--max-error", "-1"],
            "--max-error must be a finite number ≥ 0",
        ),
        (
            vec!["encode", &src, "-o", &out, "--rmse", "-0.5"],
            "--rmse must be a finite number ≥ 0",
        ),
        (
            vec!["encode", &src, "-o", &out, "--tile", "-1"],
            "--tile must be ≥ 0, not -1",
        ),
        (
            vec!["decode", &out, "-o", &y, "--threads", "-2"],
            "--threads must be ≥ 0, not -2",
        ),
        (
            vec!["encode", &src, "-o", &out, "--max-eror", "1"],
            "unexpected argument '--max-eror'",
        ),
        (vec!["encode"], "required arguments were not provided"),
        (
            vec!["decode", &out, "-o", &y, "--surface", "x"],
            "[possible values: sibson, linear, basis]",
        ),
        (vec!["frobnicate"], "unrecognized subcommand"),
    ];
    for (args, want) in cases {
        let o = vtz(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert_eq!(e.lines().count(), 1, "{args:?}: not one line:\n{e}");
        assert!(e.starts_with("vtz: "), "{args:?}: {e}");
        assert!(e.contains(want), "{args:?}: wants {want:?}: {e}");
        if !want.contains("must be a finite number") {
            // clap's errors point to the command's help (the bound's own check does not).
            assert!(e.trim_end().ends_with("--help)"), "{args:?}: {e}");
        }
        assert!(
            !e.contains("-- -"),
            "{args:?}: a tip that does not work: {e}"
        );
    }
    // The help pointer names the subcommand.
    let o = vtz(["encode", &src, "--effort", "0"]);
    assert!(
        stderr(&o).contains("(see vtz encode --help)"),
        "{}",
        stderr(&o)
    );
    // Negative values that are valid stay valid; help and version still print, exit 0.
    let o = vtz([
        "encode",
        &src,
        "-o",
        &out,
        "--png-offset",
        "-100",
        "--max-error",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for args in [vec!["--version"], vec!["encode", "--help"]] {
        let o = vtz(&args);
        assert_eq!(o.status.code(), Some(0), "{args:?}");
        assert!(!o.stdout.is_empty(), "{args:?}");
    }
}

/// One name per thing: the Sibson method is `sibson` wherever vtz names a method (`info`'s
/// sections and tiles, `verify`, GDAL's option list), `sites` (the spec's section type)
/// still accepted; `decode --help` lists every method for --section; `encode --help` says
/// what the tiles' 1024 counts; plain `info` names the residual coding; counts agree with
/// their nouns; `info`'s columns line up; the write-only options are where writing is.
#[test]
fn one_name_per_thing() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let sib = tmp(&d, "sib.vtz");
    let o = vtz([
        "encode",
        &src,
        "-o",
        &sib,
        "--method",
        "sibson,grid",
        "--max-error",
        "20",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&vtz(["info", &sib]).stdout).into_owned();
    assert!(text.contains("] sibson "), "{text}");
    assert!(!text.contains("] sites "), "{text}");
    let j = json(&vtz(["info", &sib, "--json"]));
    let methods: Vec<&str> = j["sections"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["method"].as_str())
        .collect();
    assert!(
        methods.contains(&"sibson") && methods.contains(&"grid"),
        "{j}"
    );
    // `sites`, the section type's name, is an alias: decode --section sites works.
    let o = vtz([
        "decode",
        &sib,
        "-o",
        &tmp(&d, "s.tif"),
        "--section",
        "sites",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = String::from_utf8_lossy(&vtz(["verify", &sib]).stdout).into_owned();
    assert!(v.contains("sibson ≤") && !v.contains("sites ≤"), "{v}");
    assert!(v.contains(" sections:"), "{v}");
    // GDAL's creation option list spells the method as --method does.
    let cpp = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("capi/gdal/vtzdataset.cpp"),
    )
    .unwrap();
    let list = &cpp[cpp.find("name='METHOD'").unwrap()..][..200];
    assert!(list.contains("sibson") && !list.contains("sites"), "{list}");
    // decode --help: --section lists every method.
    let help = String::from_utf8_lossy(&vtz(["decode", "--help"]).stdout).into_owned();
    let section = &help[help.find("--section").unwrap()..];
    let section = &section[..section.find("\n  -").unwrap_or(section.len())];
    for m in vtz::Method::all() {
        assert!(
            section.contains(m.name()),
            "--section leaves {} out:\n{section}",
            m.name()
        );
    }
    // encode --help: the default tile size says what it counts.
    let help = String::from_utf8_lossy(&vtz(["encode", "--help"]).stdout).into_owned();
    let tile = &help[help.find("--tile").unwrap()..];
    let tile = &tile[..tile.find("\n  -").unwrap_or(tile.len())];
    assert!(tile.contains("1024 × 1024 samples"), "{tile}");
    // compare --help: no writing options; decode and convert keep them.
    let help = String::from_utf8_lossy(&vtz(["compare", "--help"]).stdout).into_owned();
    assert!(
        !help.contains("--round") && !help.contains("--drop-georef"),
        "{help}"
    );
    let o = vtz(["compare", &src, &src, "--round"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    for cmd in ["decode", "convert"] {
        let help = String::from_utf8_lossy(&vtz([cmd, "--help"]).stdout).into_owned();
        assert!(
            help.contains("--round") && help.contains("--drop-georef"),
            "{cmd}"
        );
    }
    // Plain info names the residual coding (text and JSON), as --stats does.
    let res = tmp(&d, "res.vtz");
    let o = vtz([
        "encode",
        &src,
        "-o",
        &res,
        "--method",
        "residual",
        "--max-error",
        "1",
        "--effort",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let plain = String::from_utf8_lossy(&vtz(["info", &res]).stdout).into_owned();
    let stats = String::from_utf8_lossy(&vtz(["info", &res, "--stats"]).stdout).into_owned();
    let line = stats
        .lines()
        .find(|l| l.starts_with("residual "))
        .unwrap_or_else(|| panic!("no residual line in --stats: {stats}"));
    assert!(plain.contains(line), "plain info lacks {line:?}:\n{plain}");
    let j = json(&vtz(["info", &res, "--json"]));
    assert!(j["residual"].is_object(), "{}", j["residual"]);
    // Counts agree with their nouns; one column for section names, gdal-metadata included.
    let mut r = common::terrain(common::Kind::Fbm, 120, 80, 5, true, vtz::SampleType::I16);
    r.gdal_metadata = Some("<GDALMetadata><Item name=\"UNITS\">m</Item></GDALMetadata>".into());
    let one = tmp(&d, "one.vtz");
    std::fs::write(
        &one,
        vtz::encode(&r, &common::encode_opts(&[], None)).unwrap(),
    )
    .unwrap();
    let v = String::from_utf8_lossy(&vtz(["verify", &one]).stdout).into_owned();
    assert!(
        v.contains(" sections:") && !v.contains("(1 sections"),
        "{v}"
    );
    let text = String::from_utf8_lossy(&vtz(["info", &one]).stdout).into_owned();
    let rows: Vec<&str> = text.lines().filter(|l| l.starts_with("  [")).collect();
    assert!(rows.iter().any(|l| l.contains("gdal-metadata")), "{text}");
    let col = |l: &str| l.find(" bytes").unwrap();
    assert!(rows.iter().all(|l| col(l) == col(rows[0])), "{text}");
    // A tiled file's window of one tile: "1 tile", not "1 tiles".
    let wide = common::terrain(common::Kind::Fbm, 300, 40, 1, false, vtz::SampleType::I16);
    let mut opts = common::encode_opts(&[], Some(vtz::ErrorBound::Abs(1.0)));
    opts.tile = Some(64);
    let t = tmp(&d, "t.vtz");
    std::fs::write(&t, vtz::encode(&wide, &opts).unwrap()).unwrap();
    let o = vtz([
        "decode",
        &t,
        "-o",
        &tmp(&d, "t.tif"),
        "--window",
        "0,0,10,10",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("(1 tile,"), "{}", stderr(&o));
    // encode of a directory says so, not "an empty extension".
    let o = vtz([
        "encode",
        d.path().to_str().unwrap(),
        "-o",
        &tmp(&d, "dir.vtz"),
    ]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("is a directory"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
}

/// The README's GIS commands run without root (no `sudo`: GDAL_DRIVER_PATH finds the
/// plugin) and write their outputs in a temporary directory, never in the checkout.
#[test]
fn the_readme_gis_commands_need_no_root_and_leave_the_checkout_clean() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let blocks: Vec<&str> = readme
        .split("```sh")
        .skip(1)
        .filter_map(|b| b.split("```").next())
        .collect();
    let commands: Vec<&str> = blocks
        .iter()
        .flat_map(|b| b.lines())
        .filter(|l| !l.trim_start().starts_with('#'))
        .collect();
    assert!(
        !commands.iter().any(|l| l.contains("sudo ")),
        "{commands:#?}"
    );
    let gis = commands
        .iter()
        .find(|l| l.contains("gdal_translate"))
        .expect("the README's GDAL commands");
    assert!(gis.contains("t=$(mktemp -d)"), "{gis}");
    for out in ["kauai.tif", "kauai_gdal.vtz", "window.tif"] {
        assert!(gis.contains(out), "{out}: {gis}");
        // Every mention of the output is inside the temporary directory.
        assert_eq!(
            gis.matches(out).count(),
            gis.matches(&format!("$t/{out}")).count(),
            "{out} written outside $t: {gis}"
        );
    }
    assert!(
        commands
            .iter()
            .any(|l| l.contains("export GDAL_DRIVER_PATH=$PWD/target/gdal-plugin")),
        "{commands:#?}"
    );
}
