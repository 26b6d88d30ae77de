//! The shared corpus's lidar points (`../shared/corpus/points/ahn3_delft_cropped_{1,2}.laz`,
//! AHN3, CC0) through `vtz::formats::points`: point and ground counts, plausible RD New
//! positions, and round trips of the ground returns through LAZ (within the grid) and CSV
//! (exact). Skipped, with a message, when the files are absent.

use crate::common;

use common::{shared_corpus, skip};
use std::path::PathBuf;
use std::time::Instant;
use vtz::formats::points::{ReadPointsOptions, WritePointsOptions, read_points, write_points};

/// The path of `points/NAME` in the shared corpus, or `None` with a message.
fn laz(name: &str) -> Option<PathBuf> {
    let p = shared_corpus()?.join("points").join(name);
    if p.exists() {
        Some(p)
    } else {
        skip(&format!("{} is absent", p.display()));
        None
    }
}

#[test]
fn ahn3_counts_and_ground_returns() {
    // (file, all points, class 2 = ground)
    let cases = [
        ("ahn3_delft_cropped_1.laz", 640_510, 195_988),
        ("ahn3_delft_cropped_2.laz", 208_432, 87_130),
    ];
    let mut total = 0;
    for (name, all, ground) in cases {
        let Some(path) = laz(name) else { return };
        let t = Instant::now();
        let ps = read_points(&path, &Default::default()).unwrap();
        let all_time = t.elapsed();
        assert_eq!(ps.len(), all, "{name}");
        assert_eq!(ps.names, ["z"]);
        // Delft in RD New (EPSG:28992), heights in metres about NAP.
        let [x0, y0, x1, y1] = ps.bounds().unwrap();
        assert!(x0 > 80_000.0 && x1 < 90_000.0, "{name}: x {x0}..{x1}");
        assert!(y0 > 440_000.0 && y1 < 450_000.0, "{name}: y {y0}..{y1}");
        assert!(ps.values[0].iter().all(|z| (-20.0..200.0).contains(z)));
        total += ps.len();

        let t = Instant::now();
        let opts = ReadPointsOptions {
            class: Some(2),
            ..Default::default()
        };
        let g = read_points(&path, &opts).unwrap();
        eprintln!(
            "{name}: {} points in {:.0} ms, {} ground in {:.0} ms",
            ps.len(),
            all_time.as_secs_f64() * 1e3,
            g.len(),
            t.elapsed().as_secs_f64() * 1e3
        );
        assert_eq!(g.len(), ground, "{name}: ground returns");
    }
    assert_eq!(total, 848_942);
}

#[test]
fn ahn3_ground_round_trips() {
    let Some(path) = laz("ahn3_delft_cropped_2.laz") else {
        return;
    };
    let opts = ReadPointsOptions {
        class: Some(2),
        ..Default::default()
    };
    let g = read_points(&path, &opts).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // LAZ at the source's millimetre grid: the same points, up to float noise of the grid.
    let out = dir.path().join("ground.laz");
    write_points(&out, &g, &WritePointsOptions::default()).unwrap();
    let back = read_points(&out, &Default::default()).unwrap();
    assert_eq!(back.len(), g.len());
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-6);
    assert!(close(&back.x, &g.x) && close(&back.y, &g.y));
    assert!(close(&back.values[0], &g.values[0]));
    // CSV: exact.
    let out = dir.path().join("ground.csv");
    write_points(&out, &g, &WritePointsOptions::default()).unwrap();
    assert_eq!(read_points(&out, &Default::default()).unwrap(), g);
}
