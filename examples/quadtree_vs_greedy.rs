//! The height-map-to-mesh paper's quadtree detail selector (`src/mesh/quadtree.rs`) against
//! vtz's greedy Voronoi/Sibson sites at the same vertex count, on three corpus terrains
//! (granite cliffs, mountains, a caldera with a flat lake). For each raster and threshold T:
//! the quadtree's vertex count N, then greedy selection of N sites (`vtz encode --method
//! sibson --sites N`, through the library), and for both site sets the max error and RMSE
//! over every valid sample of
//! - the linear interpolant: piecewise planar over the Delaunay triangulation, each vertex
//!   at its sample's own height (what a mesh of those vertices shows);
//! - Sibson's natural-neighbour interpolant over the same vertices and heights;
//! - for the greedy sites also the decoded `.vtz` (`vtz compare`): Sibson over the stored
//!   heights (quantized with a step of range/4096), rounded to the sample type.
//!
//! The selector, the crate's exact Delaunay triangulation and its Sibson surface live in
//! private modules, so this example compiles them from their sources under the same module
//! paths (the same code the library runs); the greedy side uses only the public API.
//!
//! `cargo run --release --example quadtree_vs_greedy [-- T1 T2 ...]` (thresholds in %,
//! default 35 40 45 50). Prints markdown tables (benches/quadtree.md holds a run).
//! `-- --counts [T…]` prints only the quadtree's vertex counts (default T = 0, 5, …, 100).
//! `VTZ_CORPUS` names the shared corpus directory (default `../shared/corpus`).
#![forbid(unsafe_code)]

use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;
use vtz::{EncodeOptions, Method, Raster};

/// What the included sources import as `crate::error`.
mod error {
    pub use vtz::{Error, Result};
}

// The private modules, from their sources (only part of each is used here).
#[allow(dead_code)]
#[path = "../src/mesh/quadtree.rs"]
pub mod quadtree_src;
#[allow(dead_code)]
#[path = "../src/geometry/sibson/mod.rs"]
pub mod sibson_src;
#[allow(dead_code)]
#[path = "../src/geometry/triangulation.rs"]
pub mod triangulation_src;

/// `crate::geometry` as the included sources name it.
mod geometry {
    pub use super::sibson_src as sibson;
    pub use super::triangulation_src as triangulation;
}

use geometry::sibson::Surface;
use quadtree_src::{insertion_order, linear_errors, select};

/// Max error and RMSE over the valid samples of Sibson's interpolant of `sites` at their
/// samples' heights (infinite when a valid sample lies outside the sites' hull).
fn sibson_errors(r: &Raster, sites: &[(usize, usize)]) -> vtz::Result<(f64, f64)> {
    let w = r.width;
    let mut s = Surface::new();
    for i in insertion_order(sites) {
        let (x, y) = sites[i];
        s.insert_near([x as i64, y as i64], r.data[y * w + x], None)?;
    }
    s.compact();
    const BAND: usize = 64;
    let bands: Vec<Option<(f64, f64)>> = (0..r.height.div_ceil(BAND))
        .into_par_iter()
        .map(|b| {
            let (y0, bh) = (b * BAND, BAND.min(r.height - b * BAND));
            let want = |x: i64, y: i64| r.is_valid(y as usize * w + x as usize);
            let out = s.eval_window(0, y0 as i64, w, bh, want)?;
            let (mut max, mut ss) = (0.0f64, 0.0f64);
            for (k, &v) in out.iter().enumerate() {
                let i = y0 * w + k;
                if r.is_valid(i) {
                    let d = (v - r.data[i]).abs();
                    max = max.max(d);
                    ss += d * d;
                }
            }
            Some((max, ss))
        })
        .collect();
    let n = (0..r.len()).filter(|&i| r.is_valid(i)).count().max(1);
    let mut max = 0.0f64;
    let mut ss = 0.0f64;
    for b in bands {
        let Some((m, s)) = b else {
            return Ok((f64::INFINITY, f64::INFINITY));
        };
        max = max.max(m);
        ss += s;
    }
    Ok((max, (ss / n as f64).sqrt()))
}

struct Row {
    name: String,
    threshold: f64,
    n: usize,
    samples: usize,
    range: f64,
    qt_secs: f64,
    greedy_n: usize,
    greedy_secs: f64,
    qt_lin: (f64, f64),
    gr_lin: (f64, f64),
    qt_sib: (f64, f64),
    gr_sib: (f64, f64),
    gr_vtz: (f64, f64),
}

fn run(name: &str, r: &Raster, thresholds: &[f64]) -> vtz::Result<Vec<Row>> {
    let (w, h) = (r.width, r.height);
    let valid = |i: usize| r.is_valid(i);
    let samples = (0..r.len()).filter(|&i| r.is_valid(i)).count();
    let (lo, hi) = r.valid_range().unwrap_or((0.0, 0.0));
    let mut rows = Vec::new();
    for &t in thresholds {
        let t0 = Instant::now();
        let qt = select(&r.data, &valid, w, h, t)?;
        let qt_secs = t0.elapsed().as_secs_f64();
        let n = qt.len();
        eprintln!("{name} T={t}: {n} quadtree vertices ({qt_secs:.2} s); greedy …");

        let mut o = EncodeOptions::default();
        o.methods = vec![Method::SIBSON];
        o.params.sibson.sites = Some(n);
        let t1 = Instant::now();
        let bytes = vtz::encode(r, &o)?;
        let greedy_secs = t1.elapsed().as_secs_f64();
        let back = vtz::decode(&bytes)?;
        let c = vtz::metrics::compare(r, &back)?;
        let mut gr: Vec<(usize, usize)> = vtz::Decoder::new(std::io::Cursor::new(bytes.clone()))?
            .sites()?
            .iter()
            .map(|s| (s.col, s.row))
            .collect();
        gr.sort_unstable();

        rows.push(Row {
            name: name.to_string(),
            threshold: t,
            n,
            samples,
            range: hi - lo,
            qt_secs,
            greedy_n: gr.len(),
            greedy_secs,
            qt_lin: linear_errors(&r.data, &valid, w, h, &qt),
            gr_lin: linear_errors(&r.data, &valid, w, h, &gr),
            qt_sib: sibson_errors(r, &qt)?,
            gr_sib: sibson_errors(r, &gr)?,
            gr_vtz: (c.max_error, c.rmse),
        });
    }
    Ok(rows)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let counts_only = args.first().is_some_and(|a| a == "--counts");
    if counts_only {
        args.remove(0);
    }
    let mut thresholds: Vec<f64> = args
        .iter()
        .map(|a| a.parse::<f64>())
        .collect::<Result<_, _>>()?;
    if thresholds.is_empty() {
        thresholds = if counts_only {
            (0..=20).map(|k| k as f64 * 5.0).collect()
        } else {
            vec![35.0, 40.0, 45.0, 50.0]
        };
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let shared = std::env::var_os("VTZ_CORPUS")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("../shared/corpus"));
    let inputs = [
        (
            "ned1_halfdome_yosemite",
            shared.join("ned1_halfdome_yosemite.f32"),
        ),
        (
            "srtm3_N44W072_white_mountains",
            shared.join("srtm3_N44W072_white_mountains.f32"),
        ),
        ("scape_crater", root.join("corpus/scape_crater.png")),
    ];
    let mut rows = Vec::new();
    for (name, path) in &inputs {
        let r = vtz::read_path(path, &Default::default())?;
        eprintln!("{name}: {}x{} {:?}", r.width, r.height, r.sample_type);
        if counts_only {
            let valid = |i: usize| r.is_valid(i);
            for &t in &thresholds {
                let n = select(&r.data, &valid, r.width, r.height, t)?.len();
                println!(
                    "{name} T={t}: {n} vertices ({:.2} %)",
                    100.0 * n as f64 / r.len() as f64
                );
            }
            continue;
        }
        rows.extend(run(name, &r, &thresholds)?);
    }
    let f = |e: (f64, f64)| format!("{:.2} | {:.3}", e.0, e.1);
    println!("### Linear (the mesh): max error | RMSE, data units\n");
    println!(
        "| raster | T % | vertices | % of samples | quadtree max | quadtree RMSE | greedy max | greedy RMSE | RMSE ratio q/g |"
    );
    println!("|---|--:|--:|--:|--:|--:|--:|--:|--:|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {:.2} | {} | {} | {:.2} |",
            r.name,
            r.threshold,
            r.n,
            100.0 * r.n as f64 / r.samples as f64,
            f(r.qt_lin),
            f(r.gr_lin),
            r.qt_lin.1 / r.gr_lin.1
        );
    }
    println!("\n### Sibson over the same vertices: max error | RMSE, data units\n");
    println!(
        "| raster | T % | vertices | quadtree max | quadtree RMSE | greedy max | greedy RMSE | greedy .vtz max | greedy .vtz RMSE | range |"
    );
    println!("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {} | {} | {} | {:.0} |",
            r.name,
            r.threshold,
            r.n,
            f(r.qt_sib),
            f(r.gr_sib),
            f(r.gr_vtz),
            r.range
        );
    }
    println!("\n### Time (s) and greedy site count\n");
    println!("| raster | T % | quadtree select | greedy encode | greedy sites |");
    println!("|---|--:|--:|--:|--:|");
    for r in &rows {
        println!(
            "| {} | {} | {:.3} | {:.2} | {} |",
            r.name, r.threshold, r.qt_secs, r.greedy_secs, r.greedy_n
        );
    }
    Ok(())
}
