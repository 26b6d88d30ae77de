//! `vtz decode`: decompress a .vtz file into a raster file.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::{DecodeOptions, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Input .vtz file: a path, or a URL (https://…, http://…, s3://bucket/key) read by
    /// range requests (only the tiles a --window or --overview needs).
    pub input: PathBuf,
    /// Output raster; the format follows the extension (.tif, .png, .exr, .hgt, .asc, .f32).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Output format, when the extension does not tell.
    #[arg(long, value_name = "FMT")]
    pub format: Option<String>,
    /// Decode this section instead of the primary one: its index from `vtz info`, or its
    /// method (sibson, grid, haar, fis, residual; `sites` is sibson's section)
    #[arg(long, value_name = "N|METHOD")]
    pub section: Option<String>,
    /// Sites section: decode only the first N sites (a coarser surface).
    #[arg(long, value_name = "N")]
    pub sites: Option<usize>,
    /// Sites section: decode only the first K levels.
    #[arg(long, value_name = "K", conflicts_with = "sites")]
    pub level: Option<usize>,
    /// Decode only the window x,y,width,height (in samples).
    #[arg(long, value_name = "X,Y,W,H")]
    pub window: Option<String>,
    /// Decode at S times the resolution (2, 0.5, 3/2, 1e-3; exact): ⌊w·S⌋ × ⌊h·S⌋ samples
    /// over the same extent as `gdal_translate -outsize`; sites through their surface, other
    /// methods and tiled files by bicubic interpolation of the decoded samples.
    #[arg(long, value_name = "S")]
    pub scale: Option<String>,
    /// Decode overview K ≥ 1 (what GDAL shows at small scales): every 2^K-th sample of
    /// every 2^K-th row, ⌈w/2^K⌉ × ⌈h/2^K⌉, pixels 2^K times larger. The residual layer
    /// decodes only its coarse levels for it (about 1/4^K of the work); --window is then in
    /// the overview's samples. A tiled file's sample comes from the tile whose core holds it,
    /// at that tile's nearest lattice point.
    #[arg(long, value_name = "K", conflicts_with = "scale")]
    pub overview: Option<u32>,
    #[command(flatten)]
    pub threads: common::Threads,
    /// Tiled files: write nodata for a tile that is corrupt (each one reported) and decode
    /// the rest, instead of failing.
    #[arg(long)]
    pub skip_corrupt: bool,
    /// Sites files: the surface through the sites. sibson is the one the file codes (its
    /// bound holds); linear (the sites' triangles) and basis (the basis-function surface of
    /// the digital-terrain-model paper) are for comparison and ignore the bound.
    #[arg(long, default_value = "sibson", value_parser = ["sibson", "linear", "basis"])]
    pub surface: String,
    #[command(flatten)]
    pub force: common::Force,
    /// Point sets: write only the kept sites (importance order) with their stored values.
    #[arg(long)]
    pub sites_only: bool,
    /// Point sets: rasterize Sibson's surface on cells of this size (CRS units, a multiple
    /// of the file's position resolution) for raster output; nodata outside the points' hull.
    #[arg(long, value_name = "C")]
    pub cell: Option<f64>,
    /// Point sets: the value column to rasterize (default: the first).
    #[arg(long, value_name = "NAME")]
    pub column: Option<String>,
    /// Point sets with --cell: only cells at stored positions are valid (a raster encoded with
    /// --band decodes back to its grid).
    #[arg(long)]
    pub only_positions: bool,
    /// Point sets: the output's CRS, EPSG:n (replaces the file's).
    #[arg(long, value_name = "EPSG:n")]
    pub crs: Option<String>,
    #[command(flatten)]
    pub raster: RasterOpts,
    #[command(flatten)]
    pub output_opts: common::OutputOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    if a.sites_only || a.cell.is_some() || a.column.is_some() || a.only_positions || a.crs.is_some()
    {
        return Err(vtz::Error::invalid(
            "--sites-only, --cell, --column, --only-positions and --crs are for point-set files",
        ));
    }
    // Everything that can fail before the decode does: options, the output's format, its
    // directory.
    let format = common::parse_format(a.format.as_deref())?;
    if format.is_none() {
        vtz::formats::Format::from_path(&a.output)?;
    }
    common::check_output(&a.input, &a.output, a.force.force)?;
    let mut opts = DecodeOptions::default();
    if let Some(s) = a.section.as_deref() {
        opts.section = s.parse()?;
    }
    opts.sites = a.sites;
    opts.levels = a.level;
    opts.window = a.window.as_deref().map(str::parse).transpose()?;
    opts.scale = a.scale.as_deref().map(str::parse).transpose()?;
    opts.overview = a.overview;
    opts.threads = a.threads.threads;
    if a.threads.threads > 0 {
        // The GeoTIFF writer compresses its tiles on rayon's global pool: keep it to the
        // count too (the bytes are the same for any count).
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(a.threads.threads)
            .build_global();
    }
    opts.skip_corrupt = a.skip_corrupt;
    opts.surface = a.surface.parse()?;
    if opts.surface != vtz::Surface::Sibson {
        ui.say(format!(
            "note: decoding through the {} surface of the sites: the file's error bound holds for the sibson surface only",
            a.surface.to_ascii_lowercase()
        ));
    }
    let mut d =
        common::open_decoder(&a.input, opts.limits).map_err(|e| e.context(a.input.display()))?;
    let tiles = match (&d.info().tiles, opts.window) {
        (Some(t), None) => t.tiles.len() as u64,
        _ => 1,
    };
    let out_format = match format {
        Some(f) => f,
        None => vtz::formats::Format::from_path(&a.output)?,
    };
    if d.info().tiles.is_some()
        && out_format == vtz::formats::Format::GeoTiff
        && opts.scale.is_none()
        && opts.overview.is_none()
    {
        // A tiled file to GeoTIFF: band by band into a tiled GeoTIFF, never the whole raster.
        let win = ui
            .progress_tiles("decoding", tiles, |p| {
                d.options(opts.clone())
                    .decode_to_geotiff(&a.output, a.force.force, p)
            })
            .map_err(|e| e.context(a.input.display()))?;
        for s in d.skipped() {
            ui.say(format!(
                "warning: wrote nodata for {}",
                s.strip_prefix("corrupt input: ").unwrap_or(s)
            ));
        }
        ui.say(format!(
            "{}: {}x{} {} ({}, written band by band)",
            a.output.display(),
            win.width,
            win.height,
            d.output_type().describe(),
            common::count(tiles, "tile")
        ));
        return Ok(());
    }
    // One bar for the whole command: the decode's own progress (tile by tile, or stage by
    // stage of an untiled file) fills its first half, the write (one step: the formats
    // write a raster whole) the second.
    let wo = common::write_options(format, a.force.force, &a.raster, &a.output_opts);
    let raster = ui.progress("decoding", |p| {
        let raster = d
            .options(opts.clone())
            .decode_progress(&|f| p(0.5 * f))
            .map_err(|e| e.context(a.input.display()))?;
        vtz::write_path(&raster, &a.output, &wo)?;
        p(1.0);
        Ok::<_, vtz::Error>(raster)
    })?;
    for s in d.skipped() {
        ui.say(format!(
            "warning: wrote nodata for {}",
            s.strip_prefix("corrupt input: ").unwrap_or(s)
        ));
    }
    ui.say(format!(
        "{}: {}x{} {}",
        a.output.display(),
        raster.width,
        raster.height,
        common::written_type(&raster, format, &a.output)
    ));
    Ok(())
}
