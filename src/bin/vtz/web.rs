//! `vtz web`: a raster or .vtz as a raster-dem tile pyramid for web maps, in a PMTiles
//! archive MapLibre GL JS reads (with the browser decoder in `web/` for vtz tiles).

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::Result;
use vtz::web::{TileFormat, WebRequest};

#[derive(clap::Args)]
pub struct Args {
    /// Input: a georeferenced raster (geographic, or projected with an EPSG code: GeoTIFF,
    /// SRTM .hgt, ASCII grid with .prj) or a .vtz of one.
    pub input: PathBuf,
    /// Output archive (.pmtiles): tiles in the Web Mercator XYZ scheme; a local path or
    /// s3://bucket/key (written locally, then uploaded; serve it with range requests).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Tile content: vtz (default: .vtz streams within each zoom's bound, decoded in the
    /// browser by web/), or today's lossless encodings for comparison: terrarium-png,
    /// terrarium-webp, mapbox-png; or f32, the resampled heights uncompressed (for
    /// measuring other codecs on the same pyramid).
    #[arg(long, value_name = "FMT", default_value = "vtz")]
    pub format: String,
    /// Pixels a tile side: 256 or 512.
    #[arg(long, value_name = "N", default_value_t = 512)]
    pub tile_size: u32,
    /// Every zoom's bound in metres (vtz tiles). Default: --pixel-fraction of the zoom's
    /// ground pixel size.
    #[arg(long, value_name = "METRES")]
    pub max_error: Option<f64>,
    /// Without --max-error, each zoom's bound is this fraction of its ground pixel size at
    /// the data's latitude farthest from the equator.
    #[arg(long, value_name = "F", default_value_t = 0.1)]
    pub pixel_fraction: f64,
    /// The coarsest zoom.
    #[arg(long, value_name = "Z", default_value_t = 0)]
    pub min_zoom: u8,
    /// The finest zoom (default: the first whose pixels are no larger than the source's).
    #[arg(long, value_name = "Z")]
    pub max_zoom: Option<u8>,
    /// Encoder effort of the vtz tiles, 1..=9 (default: the lane coding, fastest to decode).
    #[arg(long, value_name = "N")]
    pub effort: Option<u8>,
    /// Also write each vtz tile as the Rust decoder decodes it, DIR/{z}/{x}/{y}.f32
    /// (float32, NaN = nodata): for checking another decoder.
    #[arg(long, value_name = "DIR")]
    pub dump_tiles: Option<PathBuf>,
    /// Input raster format, when the extension does not tell.
    #[arg(long, value_name = "FMT")]
    pub input_format: Option<String>,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub json: common::Json,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let in_format = common::parse_format(a.input_format.as_deref())?;
    let mut req = WebRequest::default();
    req.format = TileFormat::parse(&a.format)?;
    req.tile_size = a.tile_size;
    req.max_error = a.max_error;
    req.pixel_fraction = a.pixel_fraction;
    req.min_zoom = a.min_zoom;
    req.max_zoom = a.max_zoom;
    req.effort = a.effort;
    req.expected_dir = a.dump_tiles.clone();
    if let Some(e) = a.effort
        && !(1..=9).contains(&e)
    {
        return Err(vtz::Error::invalid(format!(
            "--effort must be in 1..=9, not {e}"
        )));
    }
    if a.dump_tiles.is_some() && req.format != TileFormat::Vtz {
        return Err(vtz::Error::invalid(
            "--dump-tiles writes decoded vtz tiles: it needs --format vtz",
        ));
    }
    req.name = a.output.file_stem().map_or_else(
        || "vtz terrain".into(),
        |s| s.to_string_lossy().into_owned(),
    );
    req.validate()?;
    common::check_not_dir(&a.input)?;
    let staged = match common::url_of(&a.output) {
        Some(url) => Some(common::Staged::new(url, a.force.force)?),
        None => {
            common::check_output(&a.input, &a.output, a.force.force)?;
            None
        }
    };
    let local = staged.as_ref().map_or(&a.output, |s| &s.local);
    let r = common::read_raster(&a.input, in_format, &a.raster)?;
    let report = ui
        .progress("tiling", |p| {
            vtz::web::write_web(&r, &req, local, a.force.force || staged.is_some(), p)
        })
        .map_err(|e| e.context(a.input.display()))?;
    if let Some(s) = &staged {
        s.upload(ui)?;
    }
    if a.json.json {
        let levels: Vec<_> = report
            .levels
            .iter()
            .map(|l| {
                serde_json::json!({
                    "zoom": l.zoom, "tiles": l.tiles, "bytes": l.bytes, "bound": l.bound,
                    "pixel_metres": l.pixel_metres, "max_error": l.max_error,
                    "samples": l.samples,
                })
            })
            .collect();
        outln!(
            "{}",
            serde_json::json!({
                "input": a.input, "output": a.output, "format": req.format.name(),
                "tile_size": report.tile_size, "bounds": report.bounds,
                "tiles": report.tiles(), "bytes": report.bytes, "levels": levels,
            })
        );
    } else {
        for l in &report.levels {
            ui.say(format!(
                "zoom {:>2}: {:>5} tiles, {:>10} bytes, pixel {:>9.2} m, bound {:>8.3} m, max error {:.3} m",
                l.zoom, l.tiles, l.bytes, l.pixel_metres, l.bound, l.max_error
            ));
        }
        ui.say(format!(
            "{}: {} {} tiles of {}², zooms {}–{}, {} bytes; every pixel within its zoom's bound \
             on the decoded tiles",
            a.output.display(),
            report.tiles(),
            req.format.name(),
            report.tile_size,
            report.levels.first().map_or(0, |l| l.zoom),
            report.levels.last().map_or(0, |l| l.zoom),
            report.bytes,
        ));
    }
    Ok(())
}
