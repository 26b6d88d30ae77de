//! `vtz encode`: read a raster, compress it into a .vtz file.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::{EncodeOptions, ErrorBound, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Input raster (.tif, .png, .exr, .hgt, .asc, .f32 + .json).
    pub input: PathBuf,
    /// Output .vtz file (default: the input with extension .vtz).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Guarantee every sample within E data units, or E% of the value range (e.g. 1%).
    #[arg(long, value_name = "E", conflicts_with = "lossless")]
    pub max_error: Option<String>,
    /// Store every sample exactly (the default when no bound is given).
    #[arg(long)]
    pub lossless: bool,
    /// Input format, when the extension does not tell (tif, png, terrain-rgb, exr, hgt, asc, f32).
    #[arg(long, value_name = "FMT")]
    pub format: Option<String>,
    /// Replace an existing output file.
    #[arg(short, long)]
    pub force: bool,
    /// Print the result as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let format = common::parse_format(a.format.as_deref())?;
    let bound = a.max_error.as_deref().map(ErrorBound::parse).transpose()?;
    let output = a
        .output
        .clone()
        .unwrap_or_else(|| common::default_output(&a.input, "vtz"));
    common::check_distinct(&a.input, &output)?;
    if !a.force && output.exists() {
        return Err(vtz::Error::invalid(format!(
            "{} exists (use --force to overwrite)",
            output.display()
        )));
    }
    let raster = ui.busy("reading", || common::read_raster(&a.input, format, &a.raster))?;
    let opts = EncodeOptions {
        max_error: bound,
        ..Default::default()
    };
    let (bytes, report) = ui.busy("encoding", || vtz::encode_report(&raster, &opts))?;
    let n = bytes.len() as u64;
    vtz::fsio::write_file(&output, bytes, a.force)?;
    let bps = vtz::metrics::bits_per_sample(n, raster.len());
    let range = raster.valid_range().map_or(0.0, |(lo, hi)| hi - lo);
    let pct = if range > 0.0 {
        100.0 * report.max_error / range
    } else {
        0.0
    };
    if a.json {
        let j = serde_json::json!({
            "input": a.input, "output": output, "bytes": n, "samples": raster.len(),
            "bits_per_sample": bps,
            "ratio": raster.sample_type.bits() as f64 / bps.max(f64::MIN_POSITIVE),
            "max_error": report.max_error, "max_error_pct": pct,
            "lossless": report.max_error == 0.0,
        });
        println!("{j}");
    } else {
        let what = if report.max_error == 0.0 {
            "lossless".to_string()
        } else {
            format!("max error ≤ {} ({pct:.3} % of range)", report.max_error)
        };
        ui.say(format!(
            "{}: {n} bytes, {bps:.3} bits/sample ({:.1}:1 against {}), {what}",
            output.display(),
            raster.sample_type.bits() as f64 / bps.max(f64::MIN_POSITIVE),
            raster.sample_type.name()
        ));
    }
    Ok(())
}
