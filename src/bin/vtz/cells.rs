//! `vtz cells`: one level's Voronoi cells of a .vtz's sites, with their residual ε, as GeoJSON, a GeoPackage or a PNG picture.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use std::time::Instant;
use vtz::{CellsRequest, Error, Limits, Result};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print a JSON summary (cells, level, sites, time) on stdout")))]
pub struct Args {
    /// Input .vtz file with a sites section (untiled).
    pub input: PathBuf,
    /// Output: .geojson/.json or .gpkg (polygons with rank, level, value, samples, eps_max,
    /// eps_rms) or .png (the cells tinted by eps_max over a hillshade).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The cells of the sites of levels 0..=K (default: the last level).
    #[arg(long, value_name = "K")]
    pub level: Option<usize>,
    /// Measure ε against this original raster instead of the file's full decode (then the
    /// error to the original is at most ε + the file's bound).
    #[arg(long, value_name = "ORIGINAL")]
    pub source: Option<PathBuf>,
    #[command(flatten)]
    pub json: common::Json,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub raster: RasterOpts,
}

enum Kind {
    GeoJson,
    GeoPackage,
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
        Some("gpkg") => Kind::GeoPackage,
        Some("png") => Kind::Png,
        _ => {
            return Err(Error::invalid(format!(
                "{}: the output must end in .geojson, .json, .gpkg or .png",
                a.output.display()
            )));
        }
    };
    common::check_output(&a.input, &a.output, a.force.force)?;
    let start = Instant::now();
    let source = match &a.source {
        Some(p) => Some(ui.busy("reading the source", || {
            common::read_raster(p, None, &a.raster)
        })?),
        None => None,
    };
    let bytes = common::read_file(&a.input)?;
    if vtz::is_points_file(&bytes) {
        if matches!(kind, Kind::Png) || a.source.is_some() {
            return Err(Error::invalid(
                "a point set's cells are written as GeoJSON or a GeoPackage, measured against its own decode (no .png, no --source)",
            ));
        }
        return points_cells(&a, &bytes, start, ui);
    }
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
        Kind::GeoPackage => {
            let name = a.source.as_ref().map(|p| p.display().to_string());
            cells.gpkg(name.as_deref())?
        }
        Kind::Png => ui.busy("drawing", || cells.png())?,
    };
    vtz::formats::write_file(&a.output, out, a.force.force)?;
    let secs = start.elapsed().as_secs_f64();
    let n = cells.cells.iter().filter(|c| c.polygon.len() >= 3).count();
    let worst = cells.cells.iter().map(|c| c.eps_max).fold(0.0, f64::max);
    if a.json.json {
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

/// The cells of a point set: the sites of levels 0..=K, ε over the decoded points (column 0).
fn points_cells(a: &Args, bytes: &[u8], start: Instant, ui: &Ui) -> Result<()> {
    let ctx = |e: Error| e.context(a.input.display());
    let h = ui
        .busy("decoding", || {
            vtz::point_hierarchy(bytes, a.level.map(|k| k + 1), Limits::default())
        })
        .map_err(ctx)?;
    let level = h.site_level.last().copied().unwrap_or(0);
    if a.level.is_some_and(|k| k >= h.levels) {
        return Err(Error::invalid(format!(
            "--level {} is past the file's last level {}",
            a.level.unwrap_or(0),
            h.levels.saturating_sub(1)
        )));
    }
    let pts: Vec<[f64; 2]> = h.samples.iter().map(|s| s.0).collect();
    let hull = vtz::cells::convex_hull(&pts);
    let cells = ui
        .busy("measuring cells", || {
            vtz::cells::voronoi_cells(&h.sites, h.samples.iter().copied(), &hull)
        })
        .map_err(ctx)?;
    let infos: Vec<vtz::cells::SiteInfo> = (0..h.sites.len())
        .map(|i| vtz::cells::SiteInfo {
            rank: i,
            level: h.site_level[i],
            value: h.site_value[i],
        })
        .collect();
    let mut about = serde_json::Map::new();
    about.insert("level".into(), level.into());
    about.insert("levels".into(), h.levels.into());
    about.insert("reference".into(), "decode".into());
    about.insert(
        "note".into(),
        "eps is measured against the file's full decode at every point; the error to the original points is at most eps + the file's bound"
            .into(),
    );
    let opts = vtz::cells::GeoJsonOptions {
        epsg: h.epsg,
        about,
    };
    let out = if a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gpkg"))
    {
        vtz::cells::gpkg(&cells, &infos, &opts, h.wkt.as_deref())?
    } else {
        vtz::cells::geojson(&cells, &infos, &opts)?
    };
    vtz::formats::write_file(&a.output, out, a.force.force)?;
    let n = cells.iter().filter(|c| c.polygon.len() >= 3).count();
    let worst = cells.iter().map(|c| c.eps_max).fold(0.0, f64::max);
    let secs = start.elapsed().as_secs_f64();
    if a.json.json {
        let v = serde_json::json!({
            "output": a.output.display().to_string(), "cells": n, "level": level,
            "levels": h.levels, "sites": h.sites.len(), "samples": h.samples.len(),
            "reference": "decode", "eps_max": worst, "seconds": secs,
        });
        outln!("{v}");
    } else {
        ui.say(format!(
            "{}: {n} cells of level {level} ({} sites), eps_max {} against the decode, {secs:.2} s",
            a.output.display(),
            h.sites.len(),
            vtz::metrics::num(worst),
        ));
    }
    Ok(())
}
