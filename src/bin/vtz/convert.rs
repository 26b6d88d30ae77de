//! `vtz convert`: read a raster in one format and write it in another.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::Result;

#[derive(clap::Args)]
pub struct Args {
    /// Input raster.
    pub input: PathBuf,
    /// Output raster; the format follows the extension.
    pub output: PathBuf,
    /// Input format, when the extension does not tell.
    #[arg(long, value_name = "FMT")]
    pub from: Option<String>,
    /// Output format, when the extension does not tell.
    #[arg(long, value_name = "FMT")]
    pub to: Option<String>,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub raster: RasterOpts,
    #[command(flatten)]
    pub output_opts: common::OutputOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let from = common::parse_format(a.from.as_deref())?;
    let to = common::parse_format(a.to.as_deref())?;
    if to.is_none() {
        vtz::formats::Format::from_path(&a.output)?;
    }
    common::check_output(&a.input, &a.output, a.force.force)?;
    let raster = ui.busy("reading", || common::read_raster(&a.input, from, &a.raster))?;
    let wo = common::write_options(to, a.force.force, &a.raster, &a.output_opts);
    ui.busy("writing", || vtz::write_path(&raster, &a.output, &wo))?;
    ui.say(format!(
        "{} → {}: {}x{} {}",
        a.input.display(),
        a.output.display(),
        raster.width,
        raster.height,
        common::written_type(&raster, to, &a.output)
    ));
    Ok(())
}
