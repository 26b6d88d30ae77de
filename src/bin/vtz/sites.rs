//! `vtz sites`: list a .vtz file's sites with their importance rank, as CSV.

use crate::common::{self, Ui};
use std::path::PathBuf;
use vtz::metrics::decimal;
use vtz::{Limits, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Input .vtz file with a sites section.
    pub input: PathBuf,
    /// Write the CSV here instead of stdout.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    pub force: common::Force,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    if let Some(p) = &a.output {
        common::check_output(&a.input, p, a.force.force)?;
    }
    let bytes = common::read_file(&a.input)?;
    let mut dec = vtz::Decoder::with_limits(std::io::Cursor::new(bytes), Limits::default())
        .map_err(|e| e.context(a.input.display()))?;
    let georef = dec.info().georef.clone();
    let sites = dec.sites().map_err(|e| e.context(a.input.display()))?;
    let mut csv = String::from("rank,level,col,row,x,y,height\n");
    let mut rank = 0usize;
    for s in &sites {
        let (level, col, row, height) = (s.level, s.col, s.row, s.height);
        // Model coordinates of the sample (its centre for area rasters).
        let (x, y) = match &georef {
            Some(g) => {
                let half = if g.raster_type == vtz::RasterType::Area {
                    0.5
                } else {
                    0.0
                };
                (
                    decimal(g.origin[0] + (col as f64 + half) * g.pixel_size[0]),
                    decimal(g.origin[1] - (row as f64 + half) * g.pixel_size[1]),
                )
            }
            None => (col.to_string(), row.to_string()),
        };
        let height = decimal(height);
        csv.push_str(&format!("{rank},{level},{col},{row},{x},{y},{height}\n"));
        rank += 1;
    }
    match &a.output {
        Some(p) => {
            vtz::formats::write_file(p, csv.into_bytes(), a.force.force)?;
            ui.say(format!("{}: {rank} sites", p.display()));
        }
        None => out!("{csv}"),
    }
    Ok(())
}
