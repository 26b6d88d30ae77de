//! `vtz tiles`: a geographic raster or .vtz as a Cesium quantized-mesh-1.0 terrain pyramid.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::{Result, TerrainRequest};

#[derive(clap::Args)]
#[command(
    mut_arg("max_error", |a| a.help(
        "Every raster sample within E data units or E% of the range of the finest level's mesh \
         (default 1%); coarser levels meet Cesium's geometric error of their zoom. Measured on \
         the decoded tiles: a zoom that misses its bound is an error (exit 1)"
    )),
    mut_arg("force", |a| a.help(
        "Replace an existing output directory (only one holding a layer.json)"
    ))
)]
pub struct Args {
    /// Input: a raster in geographic coordinates (EPSG:4326: SRTM .hgt, a geographic
    /// GeoTIFF) or a .vtz of one.
    pub input: PathBuf,
    /// Output directory: layer.json and {z}/{x}/{y}.terrain (TMS geographic scheme).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub bound: common::Bound,
    /// The finest zoom (default: the first whose tiles span at most 256 samples).
    #[arg(long, value_name = "Z")]
    pub max_zoom: Option<u8>,
    /// Leave out the oct-encoded vertex normals extension.
    #[arg(long)]
    pub no_normals: bool,
    /// Leave out the water mask extension (sea: flat regions at or below 0).
    #[arg(long)]
    pub no_water_mask: bool,
    /// Gzip each tile (serve them with Content-Encoding: gzip).
    #[arg(long)]
    pub gzip: bool,
    /// Beside each tile, {z}/{x}/{y}.json with its vertices and triangles in file order
    /// (for checking the tiles with another decoder).
    #[arg(long)]
    pub dump_json: bool,
    #[command(flatten)]
    pub format: common::InputFormat,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub json: common::Json,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let in_format = a.format.get()?;
    common::check_output_dir(&a.input, &a.output, a.force.force, "layer.json")?;
    let mut req = TerrainRequest::default();
    req.max_error = a.bound.get()?;
    req.max_zoom = a.max_zoom;
    req.normals = !a.no_normals;
    req.water_mask = !a.no_water_mask;
    req.gzip = a.gzip;
    req.expected_json = a.dump_json;
    let r = common::read_raster(&a.input, in_format, &a.raster)?;
    let report = ui
        .progress("tiling", |p| {
            vtz::write_terrain(&r, &req, &a.output, a.force.force, p)
        })
        .map_err(|e| e.context(a.input.display()))?;
    if a.json.json {
        let levels: Vec<_> = report
            .levels
            .iter()
            .map(|l| {
                serde_json::json!({
                    "zoom": l.zoom, "tiles": l.tiles, "geometric_error": l.geometric_error,
                    "target": l.target, "sites": l.sites, "vertices": l.vertices,
                    "triangles": l.triangles, "added": l.added, "samples": l.samples,
                    "max_error": l.max_error, "rmse": l.rmse, "over": l.over, "bytes": l.bytes,
                })
            })
            .collect();
        outln!(
            "{}",
            serde_json::json!({
                "input": a.input, "output": a.output, "max_error": report.bound,
                "height_step": report.height_step, "bounds": report.bounds,
                "sites": report.sites, "tiles": report.tiles(), "bytes": report.bytes(),
                "levels": levels,
            })
        );
    } else {
        for l in &report.levels {
            ui.say(format!(
                "zoom {:>2}: {:>4} tiles, {:>8} vertices, {:>9} bytes, bound {:>9.2} (max error {:.2}, RMSE {:.2})",
                l.zoom, l.tiles, l.vertices, l.bytes, l.target, l.max_error, l.rmse
            ));
        }
        // What was measured on the decoded tiles (write_terrain fails on a missed bound).
        let finest = report.levels.last().map_or(0.0, |l| l.max_error);
        ui.say(format!(
            "{}: {} tiles, {} bytes, zooms 0–{}; every sample within its zoom's bound on the \
             decoded tiles (finest zoom: max error {:.2} ≤ {})",
            a.output.display(),
            report.tiles(),
            report.bytes(),
            report.levels.len() - 1,
            finest,
            report.bound
        ));
    }
    Ok(())
}
