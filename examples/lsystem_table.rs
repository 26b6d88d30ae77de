//! The fractal-plant paper's Table I beside vtz's: for each figure whose rules survive in the
//! text (benches/lsystem/*.toml), the height-field cover's faces, vertices and edges, and the
//! run time (derive, turtle, triangulate; the median of 21 runs), then the hull cover's.
//!
//! `cargo run --release --example lsystem_table`

use std::time::Instant;
use vtz::lsystem::{Cover, LSystem, counts};

/// Why a figure has no rules file.
const MISSING: [(u32, &str); 3] = [
    (
        9,
        "Example 7: [F(a)][B(a)] grows two identical plants from one point (B's rule is cut; what survives equals F's): 64 distinct tips, the paper counts each twice",
    ),
    (
        10,
        "Example 8: [F(a)][B(a)][C(a)][D(a)], four identical plants: 64 distinct tips, the paper counts each four times",
    ),
    (14, "Example 12: its rules are lost in the extraction"),
];

/// Table I: figure, faces, vertices, edges, run time (s), iterations.
const PAPER: [(u32, usize, usize, usize, f64, u32); 13] = [
    (3, 110, 64, 172, 3.1040, 3),
    (4, 212, 125, 335, 6.5700, 3),
    (5, 244, 125, 367, 7.7510, 3),
    (6, 98, 64, 160, 3.8060, 3),
    (7, 110, 64, 172, 3.9360, 3),
    (8, 102, 64, 164, 3.8160, 3),
    (9, 222, 128, 348, 5.5280, 3),
    (10, 474, 256, 728, 7.8810, 3),
    (11, 106, 64, 168, 3.5050, 3),
    (12, 102, 64, 164, 4.2860, 2),
    (13, 36, 25, 59, 3.0950, 2),
    (14, 22, 16, 36, 2.0930, 2),
    (15, 98, 64, 160, 3.6350, 3),
];

fn main() -> vtz::Result<()> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/lsystem");
    println!(
        "| fig | file | paper F / V / E | vtz height field F / V / E (V−E+F) | paper s | vtz ms | vtz hull F / V / E (V−E+F) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (fig, f, v, e, secs, _) in PAPER {
        let prefix = format!("fig{fig:02}_");
        let file = std::fs::read_dir(&dir)
            .map_err(|e| vtz::Error::io(dir.display().to_string(), e))?
            .filter_map(|d| d.ok())
            .map(|d| d.file_name().to_string_lossy().into_owned())
            .find(|n| n.starts_with(&prefix) && n.ends_with(".toml"));
        let Some(file) = file else {
            let why = MISSING.iter().find(|m| m.0 == fig).map_or("", |m| m.1);
            println!("| {fig} | — | {f} / {v} / {e} | not reproduced: {why} | {secs:.3} | | |");
            continue;
        };
        let text = std::fs::read_to_string(dir.join(&file))
            .map_err(|e| vtz::Error::io(file.clone(), e))?;
        let ls = LSystem::from_toml(&text)?;
        let mut times = Vec::new();
        let mut mesh = None;
        for _ in 0..21 {
            let t = Instant::now();
            let plant = ls.grow()?;
            mesh = Some(Cover::HeightField.mesh(&plant.tips)?);
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        let c = counts(&mesh.expect("ran"));
        let hull = counts(&Cover::Hull.mesh(&ls.grow()?.tips)?);
        println!(
            "| {fig} | {file} | {f} / {v} / {e} | {} / {} / {} ({}) | {secs:.3} | {:.2} | {} / {} / {} ({}) |",
            c.faces,
            c.vertices,
            c.edges,
            c.euler(),
            times[times.len() / 2],
            hull.faces,
            hull.vertices,
            hull.edges,
            hull.euler()
        );
    }
    Ok(())
}
