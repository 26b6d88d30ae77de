//! Point sets end to end: the bound holds at every input point and column after a decode,
//! over the degenerate inputs the issue names (collinear, co-circular, duplicates with
//! different values, 1–3 points, national-grid coordinates with small extents, several
//! columns with their own bounds), by the library (property tests) and through the CLI
//! (bad rows, raster output with a CRS, several rasters as one point set, cells).

// Columns and group members index several parallel arrays at once.
#![allow(clippy::needless_range_loop)]

use crate::common;

use common::{ok, stderr, tmp, vtz};
use proptest::prelude::*;
use std::collections::HashMap;
use std::process::Command;
use vtz::{DecodePoints, ErrorBound, PointSet, PointsOptions};

/// Check a decode against its input: the same multiset of positions (on the resolution's
/// grid) and a one-to-one matching (Kuhn's augmenting paths, per position) of input points
/// to decoded points at the same position within every column's bound.
fn check(input: &PointSet, out: &PointSet, r: f64, bounds: &[f64]) {
    assert_eq!(input.len(), out.len(), "point count");
    assert_eq!(input.columns(), out.columns());
    let t = input.columns();
    let key = |x: f64, y: f64| ((x / r).round() as i64, (y / r).round() as i64);
    let mut groups: HashMap<(i64, i64), (Vec<usize>, Vec<usize>)> = HashMap::new();
    for i in 0..out.len() {
        groups.entry(key(out.x[i], out.y[i])).or_default().1.push(i);
        // Decoded positions are on the grid.
        assert!((out.x[i] / r - (out.x[i] / r).round()).abs() < 1e-6);
    }
    for i in 0..input.len() {
        groups
            .entry(key(input.x[i], input.y[i]))
            .or_default()
            .0
            .push(i);
    }
    for (k, (ins, outs)) in &groups {
        assert_eq!(ins.len(), outs.len(), "points at {k:?}");
        let fits = |i: usize, j: usize| {
            (0..t).all(|c| (out.values[c][j] - input.values[c][i]).abs() <= bounds[c])
        };
        let mut owner: Vec<Option<usize>> = vec![None; outs.len()];
        fn augment(
            a: usize,
            seen: &mut [bool],
            owner: &mut [Option<usize>],
            fits: &dyn Fn(usize, usize) -> bool,
        ) -> bool {
            for b in 0..owner.len() {
                if !seen[b] && fits(a, b) {
                    seen[b] = true;
                    if owner[b].is_none_or(|o| augment(o, seen, owner, fits)) {
                        owner[b] = Some(a);
                        return true;
                    }
                }
            }
            false
        }
        let f = |a: usize, b: usize| fits(ins[a], outs[b]);
        for a in 0..ins.len() {
            let mut seen = vec![false; outs.len()];
            assert!(
                augment(a, &mut seen, &mut owner, &f),
                "point {} at {k:?} ({:?}) has no decoded point within the bounds {bounds:?}: {:?}",
                ins[a],
                (0..t).map(|c| input.values[c][ins[a]]).collect::<Vec<_>>(),
                outs.iter()
                    .map(|&j| (0..t).map(|c| out.values[c][j]).collect::<Vec<_>>())
                    .collect::<Vec<_>>()
            );
        }
    }
}

/// The largest error over points alone at their position (no shared positions).
fn max_error(input: &PointSet, out: &PointSet, r: f64) -> f64 {
    let key = |x: f64, y: f64| ((x / r).round() as i64, (y / r).round() as i64);
    let at: HashMap<(i64, i64), usize> = (0..out.len())
        .map(|j| (key(out.x[j], out.y[j]), j))
        .collect();
    (0..input.len())
        .map(|i| (out.values[0][at[&key(input.x[i], input.y[i])]] - input.values[0][i]).abs())
        .fold(0.0, f64::max)
}

fn round_trip(p: &PointSet, r: f64, bounds: &[f64]) {
    let mut o = PointsOptions::new(ErrorBound::Abs(bounds[0])).resolution(r);
    for c in 1..p.columns() {
        o = o.column_bound(&p.names[c], ErrorBound::Abs(bounds[c]));
    }
    let (bytes, rep) = vtz::encode_points(p, &o, &mut |_| {}).unwrap();
    let out = vtz::decode_points(&bytes, &DecodePoints::new()).unwrap();
    check(p, &out, r, bounds);
    // (Where points share a position the check may pair them differently from the
    // encoder, so only the bound, not the reported maximum, is compared.)
    for (c, b) in bounds.iter().enumerate() {
        assert!(
            rep.columns[c].max_error <= *b,
            "reported max over the bound"
        );
    }
    // The sites alone: a subset of the positions, with their stored values.
    let s = vtz::decode_points(&bytes, &DecodePoints::new().sites_only(true)).unwrap();
    assert_eq!(s.len(), rep.sites);
    // Decoding is deterministic.
    assert_eq!(
        out,
        vtz::decode_points(&bytes, &DecodePoints::new()).unwrap()
    );
}

/// Points from integer grid coordinates `q` (steps of `r`) shifted to `base`.
fn points(q: &[(i64, i64)], base: (f64, f64), r: f64, cols: Vec<Vec<f64>>) -> PointSet {
    let n = q.len();
    let mut p = PointSet {
        x: q.iter().map(|a| base.0 + a.0 as f64 * r).collect(),
        y: q.iter().map(|a| base.1 + a.1 as f64 * r).collect(),
        names: (0..cols.len())
            .map(|c| {
                if c == 0 {
                    "z".into()
                } else {
                    format!("v{}", c + 1)
                }
            })
            .collect(),
        values: cols,
        ..Default::default()
    };
    assert!(p.values.iter().all(|c| c.len() == n));
    p.epsg = Some(28992);
    p
}

#[derive(Debug, Clone, Copy)]
enum Shape {
    Random,
    Collinear,
    CoCircular,
    Grid,
    Tiny,
}

fn shape_points(shape: Shape, n: usize, seed: u64) -> Vec<(i64, i64)> {
    let mut s = seed | 1;
    let mut rnd = move |m: i64| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s % m as u64) as i64
    };
    match shape {
        Shape::Random => (0..n).map(|_| (rnd(2000), rnd(1500))).collect(),
        Shape::Collinear => (0..n)
            .map(|_| {
                let t = rnd(500);
                (3 * t, 2 * t + 7)
            })
            .collect(),
        // Integer points on the circle x² + y² = 65² (12 distinct ones), plus its centre.
        Shape::CoCircular => {
            let ring = [
                (65, 0),
                (63, 16),
                (60, 25),
                (56, 33),
                (52, 39),
                (39, 52),
                (33, 56),
                (25, 60),
                (16, 63),
                (0, 65),
            ];
            let mut v: Vec<(i64, i64)> = Vec::new();
            for &(a, b) in &ring {
                for (sa, sb) in [(1, 1), (-1, 1), (1, -1), (-1, -1)] {
                    v.push((100 + sa * a, 100 + sb * b));
                }
            }
            v.push((100, 100));
            (0..n).map(|_| v[rnd(v.len() as i64) as usize]).collect()
        }
        // A regular grid: every square's corners are co-circular.
        Shape::Grid => (0..n).map(|_| (5 * rnd(12), 5 * rnd(9))).collect(),
        Shape::Tiny => (0..n.min(3)).map(|_| (rnd(4), rnd(4))).collect(),
    }
}

fn shape() -> impl Strategy<Value = Shape> {
    prop_oneof![
        Just(Shape::Random),
        Just(Shape::Collinear),
        Just(Shape::CoCircular),
        Just(Shape::Grid),
        Just(Shape::Tiny),
    ]
}

proptest! {
    #![proptest_config(common::proptest_config(48))]

    /// Every shape, with duplicates (points drawn with replacement share positions, with
    /// different values), national-grid offsets, one or two columns.
    #[test]
    fn degenerate_sets_hold_the_bound(
        sh in shape(),
        n in 1usize..300,
        seed in any::<u64>(),
        two in any::<bool>(),
        huge in any::<bool>(),
        b0 in 0.01f64..5.0,
        b1 in 0.001f64..1.0,
    ) {
        let q = shape_points(sh, n, seed);
        let m = q.len();
        let r = 0.01;
        let base = if huge { (155_000.0 * 40.0, 463_000.0 * 13.0) } else { (0.0, 0.0) };
        let z: Vec<f64> = q.iter().enumerate()
            .map(|(i, a)| (a.0 as f64 * 0.37).sin() * 20.0 + a.1 as f64 * 0.01 + ((i * 7919) % 13) as f64 * 0.1)
            .collect();
        let mut cols = vec![z];
        let mut bounds = vec![b0];
        if two {
            cols.push(q.iter().map(|a| ((a.0 * a.1) % 17) as f64 * 0.25).collect());
            bounds.push(b1);
        }
        let p = points(&q, base, r, cols);
        prop_assert_eq!(p.len(), m);
        round_trip(&p, r, &bounds);
    }
}

proptest! {
    #![proptest_config(common::proptest_config(12))]

    /// The same shapes through the CLI: XYZ text in (national-grid coordinates in
    /// centimetres, duplicates included), CSV out, every point within the bound.
    #[test]
    fn degenerate_sets_through_the_cli(sh in shape(), n in 1usize..200, seed in any::<u64>(), b in 0.01f64..2.0) {
        let d = tempfile::tempdir().unwrap();
        let (inp, f, out) = (tmp(&d, "p.xyz"), tmp(&d, "p.vtz"), tmp(&d, "p.csv"));
        let q = shape_points(sh, n, seed);
        let mut text = String::from("# x y z\n");
        for (i, a) in q.iter().enumerate() {
            let z = (a.0 as f64 * 0.37).sin() * 20.0 + ((i * 7919) % 13) as f64 * 0.1;
            text.push_str(&format!("{}.{:02} {}.{:02} {z:.3}\n", 155_000 + a.0 / 100, a.0 % 100, 463_000 + a.1 / 100, a.1 % 100));
        }
        write(&inp, &text);
        let bs = format!("{b}");
        ok(&vtz(["encode", &inp, "-o", &f, "--max-error", &bs, "-q"]));
        ok(&vtz(["decode", &f, "-o", &out, "-q"]));
        let a = vtz::formats::points::read_points(inp.as_ref(), &Default::default()).unwrap();
        let c = vtz::formats::points::read_points(out.as_ref(), &Default::default()).unwrap();
        check(&a, &c, 0.01, &[b]);
    }
}

#[test]
fn a_single_point_and_an_empty_set() {
    let p = points(&[(5, 5)], (1.0e6, 1.0e7), 0.01, vec![vec![42.5]]);
    round_trip(&p, 0.01, &[0.01]);
    let e = PointSet {
        names: vec!["z".into()],
        values: vec![vec![]],
        ..Default::default()
    };
    let (bytes, _) =
        vtz::encode_points(&e, &PointsOptions::new(ErrorBound::Abs(1.0)), &mut |_| {}).unwrap();
    assert_eq!(
        vtz::decode_points(&bytes, &DecodePoints::new())
            .unwrap()
            .len(),
        0
    );
}

#[test]
fn resolution_is_detected_and_national_grid_positions_are_lossless() {
    // RD New coordinates (~10⁵–10⁶ m) in millimetres over a 30 m extent.
    let q: Vec<(i64, i64)> = (0..400)
        .map(|i| ((i * 7919) % 30_000, (i * 104_729) % 20_000))
        .collect();
    let z = q.iter().map(|a| (a.0 % 1000) as f64 * 0.001).collect();
    let p = points(&q, (85_123.0, 446_789.0), 0.001, vec![z]);
    let (bytes, rep) =
        vtz::encode_points(&p, &PointsOptions::new(ErrorBound::Abs(0.01)), &mut |_| {}).unwrap();
    assert_eq!(rep.resolution, 0.001);
    assert!(rep.positions_lossless);
    let out = vtz::decode_points(&bytes, &DecodePoints::new()).unwrap();
    let mut a: Vec<(u64, u64)> =
        p.x.iter()
            .zip(&p.y)
            .map(|(x, y)| (x.to_bits(), y.to_bits()))
            .collect();
    let mut b: Vec<(u64, u64)> = out
        .x
        .iter()
        .zip(&out.y)
        .map(|(x, y)| (x.to_bits(), y.to_bits()))
        .collect();
    a.sort_unstable();
    b.sort_unstable();
    assert_eq!(a, b, "positions come back bit for bit");
}

fn write(path: &str, text: &str) {
    std::fs::write(path, text).unwrap();
}

fn xyz_text(n: usize) -> String {
    let mut s = String::new();
    for i in 0..n {
        let (x, y) = ((i * 7919) % 1000, (i * 104_729) % 700);
        let z = 10.0 * ((x as f64) / 50.0).sin() + (y as f64) / 70.0;
        s.push_str(&format!(
            "{}.{:02} {}.{:02} {:.3}\n",
            120_000 + x,
            i % 100,
            480_000 + y,
            (i * 3) % 100,
            z
        ));
    }
    s
}

#[test]
fn cli_round_trip_holds_the_bound_at_every_point() {
    let d = tempfile::tempdir().unwrap();
    let (inp, f, out) = (tmp(&d, "a.xyz"), tmp(&d, "a.vtz"), tmp(&d, "b.csv"));
    write(&inp, &xyz_text(3000));
    let o = vtz([
        "encode",
        &inp,
        "-o",
        &f,
        "--max-error",
        "0.05",
        "--json",
        "-q",
    ]);
    let j = common::json(&o);
    assert_eq!(j["points"], 3000);
    assert_eq!(j["positions_lossless"], true);
    ok(&vtz(["decode", &f, "-o", &out, "-q"]));
    let a = vtz::formats::points::read_points(inp.as_ref(), &Default::default()).unwrap();
    let b = vtz::formats::points::read_points(out.as_ref(), &Default::default()).unwrap();
    check(&a, &b, 0.01, &[0.05]);
    let w = max_error(&a, &b, 0.01);
    assert!(w > 0.04 && w <= 0.05, "{w}");
    // `info` reads it; the output is never overwritten without --force.
    let i = common::json(&vtz(["info", &f, "--json"]));
    assert_eq!(i["kind"], "points");
    assert_eq!(i["points"], 3000);
    let again = vtz(["decode", &f, "-o", &out, "-q"]);
    assert_eq!(again.status.code(), Some(2), "{}", stderr(&again));
    // LAS output: z on the LAS grid, with a note.
    let las = tmp(&d, "b.las");
    let o = vtz(["decode", &f, "-o", &las]);
    ok(&o);
    let c = vtz::formats::points::read_points(las.as_ref(), &Default::default()).unwrap();
    check(&a, &c, 0.01, &[0.05 + 0.0005 + 1e-9]);
}

#[test]
fn cli_rejects_bad_rows_and_bad_options_with_clear_errors() {
    let d = tempfile::tempdir().unwrap();
    let (inp, f) = (tmp(&d, "a.xyz"), tmp(&d, "a.vtz"));
    write(&inp, "1 2 3\n4 5 6\n7 8 nan\n");
    // A bad row is corrupt input (exit 1); bad options below are usage errors (exit 2).
    let o = vtz(["encode", &inp, "-o", &f, "--max-error", "0.1"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("line 3"), "{}", stderr(&o));
    assert!(!std::path::Path::new(&f).exists(), "no output on error");
    write(&inp, &xyz_text(50));
    for bad in [
        vec!["--xy-resolution", "0"],
        vec!["--xy-resolution", "1e-9"],
        vec!["--max-error-band", "nosuch=1"],
        vec!["--max-error-band", "z"],
        vec!["--lossless"],
    ] {
        let mut args = vec!["encode", inp.as_str(), "-o", f.as_str()];
        args.extend(bad.iter().copied());
        let o = vtz(&args);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {}", stderr(&o));
        assert_eq!(
            stderr(&o).trim().lines().count(),
            1,
            "{bad:?}: one line: {}",
            stderr(&o)
        );
    }
    // A truncated point-set file is corrupt (exit 1), never a panic.
    ok(&vtz(["encode", &inp, "-o", &f, "--max-error", "0.1", "-q"]));
    let bytes = std::fs::read(&f).unwrap();
    let cut = tmp(&d, "cut.vtz");
    std::fs::write(&cut, &bytes[..bytes.len() - 3]).unwrap();
    let o = vtz(["decode", &cut, "-o", &tmp(&d, "x.xyz")]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
}

/// Whether a GDAL tool runs here; if not, the test says so on stderr.
fn have(tool: &str, what: &str) -> bool {
    let found = Command::new(tool)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        common::skip(&format!("({tool} not found): {what}"));
    }
    found
}

#[test]
fn cli_rasterizes_the_surface_with_the_crs() {
    let d = tempfile::tempdir().unwrap();
    let (inp, f, tif) = (tmp(&d, "a.xyz"), tmp(&d, "a.vtz"), tmp(&d, "a.tif"));
    write(&inp, &xyz_text(2000));
    ok(&vtz([
        "encode",
        &inp,
        "-o",
        &f,
        "--max-error",
        "0.05",
        "-q",
    ]));
    ok(&vtz([
        "decode",
        &f,
        "-o",
        &tif,
        "--cell",
        "5",
        "--crs",
        "EPSG:28992",
        "-q",
    ]));
    let r = vtz::read_path(tif.as_ref(), &Default::default()).unwrap();
    // About 1000 m × 700 m at 5 m; outside the hull (the corners) is nodata.
    assert!(
        (190..=202).contains(&r.width) && (130..=142).contains(&r.height),
        "{}x{}",
        r.width,
        r.height
    );
    assert!(!r.is_valid(0), "a corner lies outside the hull");
    let valid = (0..r.width * r.height).filter(|&i| r.is_valid(i)).count();
    assert!(valid > r.width * r.height * 8 / 10, "{valid}");
    let g = r.georef.as_ref().unwrap();
    assert_eq!(g.epsg, Some(28992));
    // A cell that is not a multiple of the resolution is a usage error.
    let o = vtz(["decode", &f, "-o", &tmp(&d, "b.tif"), "--cell", "0.005"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    if have("gdalinfo", "GDAL reading the rasterized point set") {
        let o = Command::new("gdalinfo")
            .args(["-json", &tif])
            .output()
            .unwrap();
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let wkt = j["coordinateSystem"]["wkt"].as_str().unwrap_or("");
        assert!(wkt.contains("28992") || wkt.contains("Amersfoort"), "{wkt}");
        assert_eq!(j["size"][0], r.width);
    }
}

#[test]
fn cli_several_rasters_are_one_point_set_with_a_bound_each() {
    let d = tempfile::tempdir().unwrap();
    let (w, h) = (60, 40);
    let dsm: Vec<f64> = (0..w * h)
        .map(|i| ((i % w) as f64 * 0.3).sin() * 5.0 + 20.0)
        .collect();
    let dtm: Vec<f64> = (0..w * h).map(|i| ((i / w) as f64 * 0.05) + 1.0).collect();
    let mut a = vtz::Raster::from_values(w, h, dsm, None, vtz::SampleType::F32).unwrap();
    let mut b = vtz::Raster::from_values(w, h, dtm, None, vtz::SampleType::F32).unwrap();
    for r in [&mut a, &mut b] {
        r.georef = Some(vtz::Georef {
            origin: [85_000.0, 447_000.0],
            pixel_size: [0.5, 0.5],
            raster_type: vtz::RasterType::Area,
            epsg: Some(28992),
            wkt: None,
            geokeys: None,
        });
    }
    let (pa, pb, f) = (tmp(&d, "dsm.tif"), tmp(&d, "dtm.tif"), tmp(&d, "both.vtz"));
    vtz::write_path(&a, pa.as_ref(), &Default::default()).unwrap();
    vtz::write_path(&b, pb.as_ref(), &Default::default()).unwrap();
    let j = common::json(&vtz([
        "encode",
        &pa,
        "--band",
        &pb,
        "-o",
        &f,
        "--max-error",
        "0.25",
        "--max-error-band",
        "dtm=0.02",
        "--json",
        "-q",
    ]));
    assert_eq!(j["points"], w * h);
    assert_eq!(j["columns"][0]["name"], "dsm");
    assert!(j["columns"][1]["max_error"].as_f64().unwrap() <= 0.02);
    // Each band back to its grid, within its own bound.
    for (name, src, bound) in [("dsm", &a, 0.25), ("dtm", &b, 0.02)] {
        let out = tmp(&d, &format!("{name}_out.tif"));
        ok(&vtz([
            "decode",
            &f,
            "-o",
            &out,
            "--cell",
            "0.5",
            "--column",
            name,
            "--only-positions",
            "-q",
        ]));
        let r = vtz::read_path(out.as_ref(), &Default::default()).unwrap();
        assert_eq!((r.width, r.height), (w, h), "{name}");
        let g = r.georef.as_ref().unwrap();
        assert_eq!(g.origin, [85_000.0, 447_000.0], "{name}");
        for i in 0..w * h {
            assert!(r.is_valid(i));
            // f32 output: the bound plus the value's f32 rounding.
            let e = (r.data[i] - src.data[i]).abs();
            assert!(
                e <= bound + 1e-5 * src.data[i].abs(),
                "{name} sample {i}: {e}"
            );
        }
    }
}

#[test]
fn cli_cells_of_a_point_set_are_geojson_polygons() {
    let d = tempfile::tempdir().unwrap();
    let (inp, f, g) = (tmp(&d, "a.xyz"), tmp(&d, "a.vtz"), tmp(&d, "c.geojson"));
    write(&inp, &xyz_text(1500));
    ok(&vtz(["encode", &inp, "-o", &f, "--max-error", "0.1", "-q"]));
    let j = common::json(&vtz([
        "cells", &f, "--level", "1", "-o", &g, "--json", "-q",
    ]));
    let cells = j["cells"].as_u64().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&g).unwrap()).unwrap();
    let feats = v["features"].as_array().unwrap();
    assert_eq!(feats.len() as u64, cells);
    let total: u64 = feats
        .iter()
        .map(|f| f["properties"]["samples"].as_u64().unwrap())
        .sum();
    assert_eq!(total, 1500, "every point lies in one cell");
    for f in feats {
        let p = &f["properties"];
        assert!(p["level"].as_u64().unwrap() <= 1);
        assert!(p["eps_max"].as_f64().unwrap() >= p["eps_rms"].as_f64().unwrap());
    }
    if have("ogrinfo", "GDAL reading the cells") {
        let o = Command::new("ogrinfo")
            .args(["-so", "-al", &g])
            .output()
            .unwrap();
        let s = String::from_utf8_lossy(&o.stdout);
        assert!(s.contains(&format!("Feature Count: {cells}")), "{s}");
        for field in ["rank", "level", "value", "eps_max", "eps_rms", "samples"] {
            assert!(s.contains(field), "{field}: {s}");
        }
        // The same cells as a GeoPackage.
        let gp = tmp(&d, "c.gpkg");
        ok(&vtz(["cells", &f, "--level", "1", "-o", &gp, "-q"]));
        let o = Command::new("ogrinfo")
            .args(["-ro", "-so", "-al", &gp])
            .output()
            .unwrap();
        let s = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{s}");
        assert!(s.contains(&format!("Feature Count: {cells}")), "{s}");
        assert!(s.contains("Geometry: Polygon"), "{s}");
    }
}

/// Real lidar: the AHN3 ground returns of the shared corpus's second Delft tile (CC0),
/// 5 cm at every point, positions back exactly (the LAS grid is found).
#[test]
fn ahn3_ground_returns_hold_the_bound() {
    let Some(dir) = common::shared_corpus() else {
        return;
    };
    let path = dir.join("points/ahn3_delft_cropped_2.laz");
    if !path.exists() {
        common::skip(&format!("{} is absent", path.display()));
        return;
    }
    let ro = vtz::formats::points::ReadPointsOptions {
        class: Some(2),
        ..Default::default()
    };
    let p = vtz::formats::points::read_points(&path, &ro).unwrap();
    assert_eq!(p.len(), 87_130);
    let (bytes, rep) =
        vtz::encode_points(&p, &PointsOptions::new(ErrorBound::Abs(0.05)), &mut |_| {}).unwrap();
    assert!(rep.positions_lossless, "resolution {}", rep.resolution);
    let out = vtz::decode_points(&bytes, &DecodePoints::new()).unwrap();
    check(&p, &out, rep.resolution, &[0.05]);
    // Smaller than the raw 3 × f64 per point by a wide margin.
    assert!(
        bytes.len() * 8 < p.len() * 40,
        "{} bits/point",
        8 * bytes.len() / p.len()
    );
}

/// `vtz verify` checks a point set (version 3): checksums, a full decode, and each column's
/// stored max error and rmse against its stored bound; a flipped payload byte or a stored
/// max error over the bound fails it (exit 1).
#[test]
fn cli_verify_checks_a_point_set() {
    let d = tempfile::tempdir().unwrap();
    let golden = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/v3_points.vtz");
    let o = vtz(["verify", golden]);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("ok (point set") && text.contains("300 points"),
        "{text}"
    );
    let j = common::json(&vtz(["verify", golden, "--json"]));
    assert_eq!(j["ok"], true);
    assert_eq!(j["point_set"], true);
    assert_eq!(j["valid_samples"], 300);
    assert_eq!(j["surfaces"][0]["type"], "z");
    let bytes = std::fs::read(golden).unwrap();
    let v = vtz::verify_points(&bytes, Default::default()).unwrap();
    assert_eq!((v.valid, v.surfaces.len()), (300, 2));
    // A byte of the last payload flipped.
    let mut b = bytes.clone();
    let l = b.len();
    b[l - 3] ^= 0x10;
    let p = tmp(&d, "flip.vtz");
    std::fs::write(&p, &b).unwrap();
    let o = vtz(["verify", &p]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("checksum"));
    // Column 0 ("z", its record at 68: name_len, name, step, offset, bound, max_error,
    // rmse) claims a max error of twice its bound; the header's checksum recomputed.
    let mut b = bytes.clone();
    assert_eq!(&b[68..70], b"\x01z");
    let bound = f64::from_le_bytes(b[86..94].try_into().unwrap());
    b[94..102].copy_from_slice(&(2.0 * bound).to_le_bytes());
    let hend = 16 + u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    let crc = crc32fast::hash(&b[..hend]);
    b[hend..hend + 4].copy_from_slice(&crc.to_le_bytes());
    let p = tmp(&d, "over.vtz");
    std::fs::write(&p, &b).unwrap();
    let o = vtz(["verify", &p]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("column 0 (z)") && text.contains("bound"),
        "{text}"
    );
}
