//! `vtz render`: draw a raster or a .vtz as a hillshaded, colour-tinted PNG picture.

use crate::common::{self, RasterOpts, Ui};
use std::path::{Path, PathBuf};
use vtz::viz::hillshade::ShadeOptions;
use vtz::{Error, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Input raster or .vtz file.
    pub input: PathBuf,
    /// Output PNG picture.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub format: common::InputFormat,
    /// Mark the sites a .vtz kept (its primary section must be a sites section) as red dots.
    #[arg(long)]
    pub sites: bool,
    /// Direction the light comes from, degrees clockwise from north.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 315.0,
        allow_negative_numbers = true
    )]
    pub azimuth: f64,
    /// Height of the light above the horizon, degrees (0-90).
    #[arg(long, value_name = "DEG", default_value_t = 45.0)]
    pub altitude: f64,
    /// Vertical exaggeration (e.g. for rasters without a georef whose pixels are not 1 unit).
    #[arg(
        long,
        value_name = "Z",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    pub z_factor: f64,
    /// Draw every sample as an N x N block (for small rasters).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub scale: u32,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let format = a.format.get()?;
    common::check_output(&a.input, &a.output, a.force.force)?;
    if a.sites && !common::is_vtz(&a.input, format) {
        return Err(Error::invalid("--sites needs a .vtz input"));
    }
    let raster = ui.busy("reading", || {
        common::read_raster(&a.input, format, &a.raster)
    })?;
    let sites = if a.sites {
        let s = ui
            .busy("decoding sites", || site_positions(&a.input))
            .map_err(|e| e.context(a.input.display()))?;
        Some(s)
    } else {
        None
    };
    let n_sites = sites.as_ref().map(Vec::len);
    let opts = ShadeOptions {
        azimuth: a.azimuth,
        altitude: a.altitude,
        z_factor: a.z_factor,
        sites,
        scale: a.scale,
    };
    let png = ui.busy("rendering", || {
        vtz::viz::hillshade::hillshade(&raster, &opts)
    })?;
    vtz::formats::write_file(&a.output, png, a.force.force)?;
    let mut msg = format!(
        "{}: {}x{} picture",
        a.output.display(),
        raster.width * a.scale as usize,
        raster.height * a.scale as usize
    );
    if let Some(n) = n_sites {
        msg.push_str(&format!(", {n} sites marked"));
    }
    ui.say(msg);
    Ok(())
}

/// The (column, row) of every site of a .vtz file's sites section.
fn site_positions(path: &Path) -> Result<Vec<(usize, usize)>> {
    let bytes = common::read_file(path)?;
    let sites = vtz::Decoder::new(std::io::Cursor::new(bytes))
        .and_then(|mut d| d.sites())
        .map_err(|e| e.context("--sites needs a .vtz with a sites section"))?;
    Ok(sites.iter().map(|s| (s.col, s.row)).collect())
}
