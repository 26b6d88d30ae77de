//! `vtz verify`: check .vtz files end to end, one line per file.

use crate::common::{self, Ui};
use std::path::{Path, PathBuf};
use vtz::metrics::num;
use vtz::{Limits, Result};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print one JSON object per file on stdout instead of text")))]
pub struct Args {
    /// The .vtz files to check: paths, or URLs (https://…, http://…, s3://bucket/key).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    #[command(flatten)]
    pub json: common::Json,
}

/// Check every file; exit 1 when any has a problem (all are checked and reported).
pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let mut failed = 0usize;
    for f in &a.files {
        let res = ui.busy(&format!("verifying {}", f.display()), || check(f));
        match (&res, a.json.json) {
            (Ok(v), false) if v.point_set => {
                let cols: Vec<String> = v
                    .surfaces
                    .iter()
                    .map(|(_, name, b)| format!("{name} ≤ {}", num(*b)))
                    .collect();
                outln!(
                    "{}: ok (point set, {}: checksums, decodes, {} points, stored max errors within their bounds: {})",
                    f.display(),
                    common::count(v.sections as u64, "section"),
                    v.valid,
                    cols.join(", ")
                );
            }
            (Ok(v), false) if v.tiles > 0 => {
                let worst = v.surfaces.iter().map(|s| s.2).fold(0.0, f64::max);
                outln!(
                    "{}: ok ({}, {}: checksums, decodes, {} coded samples within their tiles' stored ranges and max errors, the largest {})",
                    f.display(),
                    common::count(v.tiles as u64, "tile"),
                    common::count(v.sections as u64, "section"),
                    v.valid,
                    num(worst)
                );
            }
            (Ok(v), false) => {
                let surfaces: Vec<String> = v
                    .surfaces
                    .iter()
                    .map(|(i, name, b)| format!("[{i}] {name} ≤ {}", num(*b)))
                    .collect();
                let unknown = if v.unknown.is_empty() {
                    String::new()
                } else {
                    format!(
                        ", {} unknown optional section(s) checksummed only",
                        v.unknown.len()
                    )
                };
                outln!(
                    "{}: ok ({}: checksums, decodes, {} valid samples within the stored range and max error of {}{unknown})",
                    f.display(),
                    common::count(v.sections as u64, "section"),
                    v.valid,
                    surfaces.join(", ")
                );
            }
            (Ok(v), true) => outln!(
                "{}",
                serde_json::json!({
                    "file": f, "ok": true, "sections": v.sections, "valid_samples": v.valid,
                    "surfaces": v.surfaces.iter().map(|(i, name, b)| serde_json::json!({
                        "index": i, "type": name, "max_error": b})).collect::<Vec<_>>(),
                    "unknown_sections": v.unknown, "tiles": v.tiles, "point_set": v.point_set,
                })
            ),
            (Err(e), false) => outln!("{}: FAILED: {e}", f.display()),
            (Err(e), true) => outln!(
                "{}",
                serde_json::json!({"file": f, "ok": false, "error": e.to_string()})
            ),
        }
        failed += usize::from(res.is_err());
    }
    if failed > 0 {
        return Err(vtz::Error::corrupt(format!(
            "{failed} of {} files failed verification",
            a.files.len()
        )));
    }
    Ok(())
}

fn check(path: &Path) -> Result<vtz::Verified> {
    if crate::common::is_points_file(path)? {
        return vtz::verify_points(&crate::common::read_file(path)?, Limits::default());
    }
    common::open_decoder(path, Limits::default())?.verify()
}
