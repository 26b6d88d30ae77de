//! `vtz lsystem`: a 3D L-system's tips as scattered points (.xyz) or covered by triangles
//! (a mesh: .obj, .ply, .stl, .glb).

use crate::common::{self, Ui};
use std::path::{Path, PathBuf};
use vtz::lsystem::{Cover, LSystem, counts};
use vtz::{MeshFormat, Result};

#[derive(clap::Args)]
pub struct Args {
    /// The L-system: a TOML file with axiom, iterations, alpha/beta/gamma (degrees), length,
    /// frame ("local" or "fixed") and a [rules] table (benches/lsystem/ has the paper's).
    pub rules: PathBuf,
    /// Output: .xyz (the tips, one "x y z" line each) or a mesh (.obj, .ply, .stl, .glb).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The mesh's cover: heightfield (2D Delaunay of x, y; the paper's Table I) or hull (the
    /// 3D convex hull, a closed cover).
    #[arg(long, default_value = "heightfield", value_parser = ["heightfield", "hull"])]
    pub cover: String,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub json: common::Json,
}

fn is_xyz(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("xyz"))
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let mesh_format = if is_xyz(&a.output) {
        None
    } else {
        Some(MeshFormat::from_path(&a.output).map_err(|_| {
            vtz::Error::invalid(format!(
                "{}: the output must be .xyz (points) or a mesh (.obj, .ply, .stl, .glb)",
                a.output.display()
            ))
        })?)
    };
    let cover: Cover = a.cover.parse()?;
    common::check_output(&a.rules, &a.output, a.force.force)?;
    let text = std::fs::read_to_string(&a.rules)
        .map_err(|e| vtz::Error::io(a.rules.display().to_string(), e))?;
    let start = std::time::Instant::now();
    let ls = LSystem::from_toml(&text).map_err(|e| e.context(a.rules.display()))?;
    let plant = ls.grow().map_err(|e| e.context(a.rules.display()))?;
    let (bytes, mesh_counts) = match mesh_format {
        None => (xyz(&plant.tips), None),
        Some(f) => {
            let mesh = cover.mesh(&plant.tips)?;
            (vtz::encode_mesh(&mesh, f)?, Some(counts(&mesh)))
        }
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let n = bytes.len();
    vtz::formats::write_file(&a.output, bytes, a.force.force)?;
    if a.json.json {
        outln!(
            "{}",
            serde_json::json!({
                "rules": a.rules, "output": a.output, "modules": plant.modules,
                "segments": plant.segments.len(), "tips": plant.tips.len(),
                "cover": mesh_counts.map(|_| a.cover.as_str()),
                "faces": mesh_counts.map(|c| c.faces), "vertices": mesh_counts.map(|c| c.vertices),
                "edges": mesh_counts.map(|c| c.edges), "bytes": n, "ms": ms,
            })
        );
    } else {
        let what = mesh_counts.map_or_else(
            || format!("{} tips", plant.tips.len()),
            |c| {
                format!(
                    "{} cover of {} tips: {} faces, {} vertices, {} edges",
                    a.cover,
                    plant.tips.len(),
                    c.faces,
                    c.vertices,
                    c.edges
                )
            },
        );
        ui.say(format!(
            "{}: {what}, {n} bytes ({} modules, {ms:.1} ms)",
            a.output.display(),
            plant.modules
        ));
    }
    Ok(())
}

/// One "x y z" line per point, shortest round-trip decimals.
fn xyz(points: &[[f64; 3]]) -> Vec<u8> {
    let mut s = String::with_capacity(points.len() * 40);
    for p in points {
        s.push_str(&format!("{} {} {}\n", p[0], p[1], p[2]));
    }
    s.into_bytes()
}
