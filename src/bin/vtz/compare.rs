//! `vtz compare`: error statistics between a reference raster and another (either may be .vtz).

use crate::common::{self, RasterOpts, Ui};
use std::path::{Path, PathBuf};
use vtz::Result;
use vtz::metrics::num;

#[derive(clap::Args)]
#[command(
    mut_arg("json", |a| a.help("Print JSON on stdout instead of text")),
    mut_arg("force", |a| a.help("Replace an existing --png file"))
)]
pub struct Args {
    /// Reference raster (or .vtz).
    pub a: PathBuf,
    /// Raster to compare with it (or .vtz).
    pub b: PathBuf,
    #[command(flatten)]
    pub json: common::Json,
    /// Also write a PNG map of B − A (blue negative, white 0, red positive, scaled to the
    /// max error) with a colour bar.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    if let Some(png) = &a.png {
        common::check_distinct(&a.a, png)?;
        common::check_output(&a.b, png, a.force.force)?;
    }
    let ra = ui.busy("reading", || common::read_raster(&a.a, None, &a.raster))?;
    let rb = ui.busy("reading", || common::read_raster(&a.b, None, &a.raster))?;
    let c = vtz::metrics::compare(&ra, &rb)?;
    if let Some(png) = &a.png {
        let map = ui.busy("drawing", || vtz::viz::hillshade::error_map(&ra, &rb, None))?;
        vtz::formats::write_file(png, map, a.force.force)?;
        ui.say(format!(
            "{}: error map, full colour at ±{}",
            png.display(),
            num(c.max_error)
        ));
    }
    let vtz_size = |p: &Path| -> Option<u64> {
        common::is_vtz(p, None)
            .then(|| std::fs::metadata(p).ok().map(|m| m.len()))
            .flatten()
    };
    let bytes = vtz_size(&a.b).or_else(|| vtz_size(&a.a));
    let bps = bytes.map(|n| vtz::metrics::bits_per_sample(n, ra.len()));
    if a.json.json {
        let mut j = serde_json::to_value(&c).unwrap_or_default();
        j["bits_per_sample"] = serde_json::json!(bps);
        j["vtz_bytes"] = serde_json::json!(bytes);
        j["value_scale"] = serde_json::json!(ra.mapping.scale);
        j["value_offset"] = serde_json::json!(ra.mapping.offset);
        outln!("{j}");
        return Ok(());
    }
    outln!(
        "size        {} x {} ({} valid samples)",
        c.width,
        c.height,
        c.valid
    );
    if !ra.mapping.is_identity() {
        outln!(
            "values      {} + {} * code ({} codes): errors are in values",
            ra.mapping.offset,
            ra.mapping.scale,
            ra.sample_type.name()
        );
    }
    outln!(
        "max error   {} ({} % of range {})",
        num(c.max_error),
        num(c.max_error_pct),
        num(c.range)
    );
    outln!(
        "rmse        {} ({} % of range)",
        num(c.rmse),
        num(c.rmse_pct)
    );
    outln!("mean |err|  {}", num(c.mean_abs_error));
    outln!("psnr        {:.2} dB", c.psnr_db);
    if let Some(b) = bps {
        outln!("bits/sample {b:.4} ({} bytes)", bytes.unwrap_or(0));
    }
    if c.lost > 0 || c.invented > 0 {
        outln!(
            "nodata      {} valid samples lost, {} nodata samples filled",
            c.lost,
            c.invented
        );
    }
    outln!("identical   {}", if c.identical { "yes" } else { "no" });
    Ok(())
}
