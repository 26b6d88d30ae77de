//! `vtz cells`: one level's Voronoi cells of a .vtz's sites, with their residual ε, as GeoJSON or a PNG picture.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use std::time::Instant;
use vtz::{CellsRequest, Error, Limits, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Input .vtz file with a sites section (untiled).
    pub input: PathBuf,
    /// Output: .geojson/.json (polygons with rank, level, value, samples, eps_max, eps_rms)
    /// or .png (the cells tinted by eps_max over a hillshade).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The cells of the sites of levels 0..=K (default: the last level).
    #[arg(long, value_name = "K")]
    pub level: Option<usize>,
    /// Measure ε against this original raster instead of the file's full decode (then the
    /// error to the original is at most ε + the file's bound).
    #[arg(long, value_name = "ORIGINAL")]
    pub source: Option<PathBuf>,
    /// Print a JSON summary (cells, level, sites, time) on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace an existing output file.
    #[arg(short, long)]
    pub force: bool,
    #[command(flatten)]
    pub raster: RasterOpts,
}

enum Kind {
    GeoJson,
    Png,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let kind = match ext.as_deref() {
        Some("geojson" | "json") => Kind::GeoJson,
        Some("png") => Kind::Png,
        _ => {
            return Err(Error::invalid(format!(
                "{}: the output must end in .geojson, .json or .png",
                a.output.display()
            )));
        }
    };
    common::check_output(&a.input, &a.output, a.force)?;
    let start = Instant::now();
    let source = match &a.source {
        Some(p) => Some(ui.busy("reading the source", || {
            common::read_raster(p, None, &a.raster)
        })?),
        None => None,
    };
    let bytes = common::read_file(&a.input)?;
    let req = CellsRequest {
        level: a.level,
        source: source.as_ref(),
        limits: Limits::default(),
    };
    let cells = ui
        .busy("measuring cells", || {
            vtz::file_cells(std::io::Cursor::new(bytes), &req)
        })
        .map_err(|e| e.context(a.input.display()))?;
    let out = match kind {
        Kind::GeoJson => {
            let name = a.source.as_ref().map(|p| p.display().to_string());
            cells.geojson(name.as_deref())?
        }
        Kind::Png => ui.busy("drawing", || cells.png())?,
    };
    vtz::formats::write_file(&a.output, out, a.force)?;
    let secs = start.elapsed().as_secs_f64();
    let n = cells.cells.iter().filter(|c| c.polygon.len() >= 3).count();
    let worst = cells.cells.iter().map(|c| c.eps_max).fold(0.0, f64::max);
    if a.json {
        let v = serde_json::json!({
            "output": a.output.display().to_string(),
            "cells": n,
            "level": cells.level,
            "levels": cells.levels,
            "sites": cells.sites.len(),
            "file_sites": cells.total_sites,
            "samples": cells.valid,
            "reference": if cells.from_source { "source" } else { "decode" },
            "eps_max": worst,
            "file_max_error": cells.bound,
            "seconds": secs,
        });
        outln!("{v}");
    } else {
        ui.say(format!(
            "{}: {n} cells of level {} ({} of {} sites), eps_max {} against the {}, {:.2} s",
            a.output.display(),
            cells.level,
            cells.sites.len(),
            cells.total_sites,
            vtz::metrics::num(worst),
            if cells.from_source {
                "source"
            } else {
                "decode"
            },
            secs
        ));
    }
    Ok(())
}
