//! `vtz mesh`, `vtz tiles` and `--surface` through the binary: results, exit codes, output
//! never half-written or clobbered. (The exporters' files are read back by independent
//! parsers in the library's tests and by the Khronos validator and an npm quantized-mesh
//! decoder in `.ci/run`.)

use crate::common;

use common::{corpus, json, stderr, tmp, vtz};
use std::path::Path;
use std::process::Command;

fn code(o: &std::process::Output) -> i32 {
    o.status.code().unwrap_or(-1)
}

#[test]
fn mesh_writes_each_format_and_refuses_bad_options() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("scape_crater.png");
    for ext in ["obj", "ply", "stl", "glb"] {
        let out = tmp(&d, &format!("m.{ext}"));
        let j = json(&vtz([
            "mesh",
            &src,
            "-o",
            &out,
            "--max-error",
            "10",
            "--normals",
            "--json",
        ]));
        // The bound holds for the mesh's triangles at every valid sample.
        assert!(j["max_error"].as_f64().unwrap() <= 10.0, "{j}");
        assert_eq!(j["samples"], 154_224);
        assert!(j["vertices"].as_u64().unwrap() > 100, "{j}");
        assert!(j["triangles"].as_u64().unwrap() > j["vertices"].as_u64().unwrap());
        assert_eq!(
            std::fs::metadata(&out).unwrap().len(),
            j["bytes"].as_u64().unwrap()
        );
    }
    // A threshold outside 0–100 % is a usage error, and nothing is written.
    let out = tmp(&d, "q.obj");
    for t in ["150", "-1"] {
        let o = vtz([
            "mesh",
            &src,
            "-o",
            &out,
            "--select",
            "quadtree",
            &format!("--threshold={t}"),
        ]);
        assert_eq!(code(&o), 2, "{}", stderr(&o));
        assert!(stderr(&o).contains("threshold"), "{}", stderr(&o));
        assert!(!Path::new(&out).exists());
    }
    // An unknown mesh format, and an existing output without --force.
    let o = vtz(["mesh", &src, "-o", &tmp(&d, "m.fbx")]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    let before = std::fs::read(tmp(&d, "m.obj")).unwrap();
    let o = vtz(["mesh", &src, "-o", &tmp(&d, "m.obj"), "--max-error", "5%"]);
    assert_ne!(code(&o), 0);
    assert_eq!(std::fs::read(tmp(&d, "m.obj")).unwrap(), before);
    // --surface belongs to a .vtz's sites.
    let o = vtz(["mesh", &src, "-o", &tmp(&d, "s.obj"), "--surface", "basis"]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
}

#[test]
fn quadtree_meshes_follow_the_threshold() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("scape_crater.png");
    let n = |t: &str| {
        let j = json(&vtz([
            "mesh",
            &src,
            "-o",
            &tmp(&d, &format!("q{t}.ply")),
            "--select",
            "quadtree",
            "--threshold",
            t,
            "--json",
        ]));
        j["vertices"].as_u64().unwrap()
    };
    // A lower threshold splits more quadrants.
    assert!(
        n("25") > n("32"),
        "threshold 25 should keep more vertices than 32"
    );
}

#[test]
fn surfaces_other_than_sibson_decode_sites_files_only() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let sites = tmp(&d, "s.vtz");
    let o = vtz([
        "encode",
        &src,
        "-o",
        &sites,
        "--method",
        "sibson",
        "--max-error",
        "10",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rmse = |surface: &str| {
        let out = tmp(&d, &format!("{surface}.tif"));
        let o = vtz(["decode", &sites, "-o", &out, "--surface", surface]);
        assert!(o.status.success(), "{}", stderr(&o));
        if surface != "sibson" {
            assert!(stderr(&o).contains("bound holds for the sibson surface only"));
        }
        let c = json(&vtz(["compare", &src, &out, "--json"]));
        (
            c["rmse"].as_f64().unwrap(),
            c["max_error"].as_f64().unwrap(),
        )
    };
    let (sibson, sibson_max) = rmse("sibson");
    let (linear, _) = rmse("linear");
    let (basis, _) = rmse("basis");
    assert!(sibson_max <= 10.0);
    // The coded surface is the best of the three on these sites (benches/basis_study.md).
    assert!(
        sibson < linear && sibson < basis,
        "{sibson} {linear} {basis}"
    );
    // A residual file has no surface to swap.
    let res = tmp(&d, "r.vtz");
    let o = vtz([
        "encode",
        &src,
        "-o",
        &res,
        "--method",
        "residual",
        "--max-error",
        "10",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = vtz([
        "decode",
        &res,
        "-o",
        &tmp(&d, "x.tif"),
        "--surface",
        "linear",
    ]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(!Path::new(&tmp(&d, "x.tif")).exists());
}

/// Every tile file of a pyramid, by path relative to its directory, with its bytes.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(p) = stack.pop() {
        for e in std::fs::read_dir(&p).unwrap() {
            let e = e.unwrap().path();
            if e.is_dir() {
                stack.push(e);
            } else {
                let rel = e.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.push((rel, std::fs::read(&e).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn tiles_meet_their_bounds_list_every_tile_and_do_not_depend_on_threads() {
    let d = tempfile::tempdir().unwrap();
    let src = corpus("srtm3_N22W160_kauai.hgt");
    let run = |name: &str, threads: &str| {
        let out = d.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_vtz"))
            .args(["tiles", &src, "-o"])
            .arg(&out)
            .args(["--max-error", "5", "--dump-json", "--json"])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        (out, json(&o))
    };
    let (a, j) = run("a", "1");
    let (b, _) = run("b", "2");
    // Same files, same bytes (layer.json names its directory, so compare it without).
    let tiles = |d: &Path| -> Vec<(String, Vec<u8>)> {
        files(d)
            .into_iter()
            .filter(|f| f.0 != "layer.json")
            .collect()
    };
    let (ta, tb) = (tiles(&a), tiles(&b));
    assert!(ta.len() > 100);
    assert!(ta == tb, "tiles differ between 1 and 2 threads");
    let layer = |d: &Path| {
        let mut j: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join("layer.json")).unwrap()).unwrap();
        j["name"] = serde_json::Value::Null;
        j
    };
    assert_eq!(layer(&a), layer(&b));
    assert_eq!(j["max_error"], 5.0);
    let levels = j["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 11, "zooms 0–10 for 3″ data");
    for l in levels {
        let (max, target) = (
            l["max_error"].as_f64().unwrap(),
            l["target"].as_f64().unwrap(),
        );
        assert!(max <= target, "zoom {}: {max} > {target}", l["zoom"]);
        assert_eq!(l["over"], 0);
        assert!(
            l["samples"].as_u64().unwrap() >= 1_438_122,
            "every valid sample measured"
        );
    }
    assert_eq!(levels[10]["target"], 5.0);
    // Coarser levels have fewer vertices.
    let v = |z: usize| levels[z]["vertices"].as_u64().unwrap();
    assert!(v(8) < v(9) && v(9) < v(10));
    // layer.json lists exactly the tiles written.
    let layer: serde_json::Value =
        serde_json::from_slice(&std::fs::read(a.join("layer.json")).unwrap()).unwrap();
    assert_eq!(layer["format"], "quantized-mesh-1.0");
    assert_eq!(layer["scheme"], "tms");
    assert_eq!(
        layer["extensions"],
        serde_json::json!(["octvertexnormals", "watermask"])
    );
    let mut listed = Vec::new();
    for (z, ranges) in layer["available"].as_array().unwrap().iter().enumerate() {
        for r in ranges.as_array().unwrap() {
            let g = |k: &str| r[k].as_u64().unwrap();
            for x in g("startX")..=g("endX") {
                for y in g("startY")..=g("endY") {
                    listed.push(format!("{z}/{x}/{y}.terrain"));
                }
            }
        }
    }
    listed.sort();
    let mut written: Vec<String> = files(&a)
        .into_iter()
        .map(|f| f.0)
        .filter(|f| f.ends_with(".terrain"))
        .collect();
    written.sort();
    assert_eq!(listed, written);
    assert_eq!(written.len() as u64, j["tiles"].as_u64().unwrap());
    // Each tile's vertex count (after the 88-byte header) is the one its JSON lists.
    for t in &written {
        let bytes = std::fs::read(a.join(t)).unwrap();
        let n = u32::from_le_bytes(bytes[88..92].try_into().unwrap()) as usize;
        let exp: serde_json::Value =
            serde_json::from_slice(&std::fs::read(a.join(t.replace(".terrain", ".json"))).unwrap())
                .unwrap();
        assert_eq!(exp["vertices"].as_array().unwrap().len(), n, "{t}");
    }
}

#[test]
fn tiles_refuse_projected_input_fine_bounds_and_foreign_directories() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("t");
    let o = vtz([
        "tiles",
        &corpus("srtm30m_bigtujunga_utm11.tif"),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(stderr(&o).contains("EPSG:4326") && stderr(&o).contains("EPSG:32611"));
    assert_eq!(stderr(&o).trim().lines().count(), 1);
    assert!(!out.exists());
    let kauai = corpus("srtm3_N22W160_kauai.hgt");
    let o = vtz([
        "tiles",
        &kauai,
        "-o",
        out.to_str().unwrap(),
        "--max-error",
        "0.01",
    ]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("height step"), "{}", stderr(&o));
    assert!(!out.exists());
    // A directory that is not a pyramid is never replaced, even with --force.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "mine").unwrap();
    for force in [false, true] {
        let mut args = vec![
            "tiles",
            &kauai,
            "-o",
            out.to_str().unwrap(),
            "--max-zoom",
            "6",
        ];
        if force {
            args.push("--force");
        }
        let o = vtz(args);
        assert_eq!(code(&o), 2, "{}", stderr(&o));
        assert_eq!(
            std::fs::read_to_string(out.join("keep.txt")).unwrap(),
            "mine"
        );
    }
    // A previous pyramid is replaced with --force, and no temporary directory is left.
    let p = d.path().join("p");
    for _ in 0..2 {
        let o = vtz([
            "tiles",
            &kauai,
            "-o",
            p.to_str().unwrap(),
            "--max-zoom",
            "6",
            "-f",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let left: Vec<_> = std::fs::read_dir(d.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("vtz-tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
