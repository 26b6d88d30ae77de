//! `vtz encode`: read a raster, compress it into a .vtz file.

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::metrics::num;
use vtz::{EncodeOptions, ErrorBound, Result};

#[derive(clap::Args)]
#[command(
    mut_arg("max_error", |a| a.help(
        "Guarantee every sample within E data units, or E% of the value range (e.g. 1%)"
    )),
    mut_arg("threads", |a| a.help(
        "Threads for a tiled encode (default: all cores); the file is the same for any count"
    ))
)]
pub struct Args {
    /// Input raster (.tif, .png, .exr, .hgt, .asc, .f32 + .json), or scattered points
    /// (.xyz .txt .csv .las .laz) encoded as a point set.
    pub input: PathBuf,
    /// Output .vtz file (default: the input with extension .vtz), or s3://bucket/key
    /// (written to a temporary file, then uploaded; nothing is left on a failure).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Where the output is shown to go (`-o s3://…`: the URL, while `output` is the local
    /// file staged for the upload).
    #[arg(skip)]
    pub shown_output: Option<PathBuf>,
    /// `-o s3://…`: the upload of `output` once written, before the summary is printed.
    #[arg(skip)]
    pub staged: Option<Box<common::Staged>>,
    #[command(flatten)]
    pub bound: common::Bound,
    /// Store every sample exactly (the default when no bound is given).
    #[arg(long, conflicts_with_all = ["max_error", "sites", "rmse"])]
    pub lossless: bool,
    /// Aim for at most B bits per sample (the smallest bound that fits, by bisection).
    #[arg(long, value_name = "B", conflicts_with_all = ["max_error", "lossless", "sites", "rmse", "size"])]
    pub bps: Option<f64>,
    /// Aim for a file of at most this many bytes (the smallest bound that fits).
    #[arg(long, value_name = "BYTES", conflicts_with_all = ["max_error", "lossless", "sites", "rmse"])]
    pub size: Option<u64>,
    /// Sibson sites: stop at N sites (a coarser surface; the bound is what it achieves, so
    /// it excludes --max-error and --rmse).
    #[arg(long, value_name = "N", conflicts_with_all = ["max_error", "rmse"])]
    pub sites: Option<usize>,
    /// Sibson sites: stop when the RMSE is at most E data units or E% of the range.
    #[arg(long, value_name = "E")]
    pub rmse: Option<String>,
    /// Representation: best (smallest that meets the request), sibson (alias sites), grid,
    /// haar, fis, residual; a comma list (sibson,fis,haar) writes each as a section, the
    /// smallest as the primary.
    #[arg(long, default_value = "best")]
    pub method: String,
    /// FIS: interpolation points every K samples (default: the cheapest K that meets the bound).
    #[arg(long, value_name = "K")]
    pub fis_k: Option<usize>,
    /// FIS: one vertical scaling factor S for all rectangles (the paper used 0.02) instead of
    /// fitted per-rectangle factors.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub fis_s: Option<f64>,
    /// Sibson: height quantization step as a multiple of the error target (tuning).
    #[arg(long, value_name = "F", hide = true)]
    pub step_factor: Option<f64>,
    /// Sibson refinement norm: linf (worst sample) or l2 (worst tile by RMS).
    #[arg(long, default_value = "linf")]
    pub norm: String,
    /// Encoder effort 1..=9: higher tries more predictors and bin layouts for a smaller
    /// file. 1–5 (default 5) write the residual layer's lane coding (the fastest to decode:
    /// vectorised rows, four interleaved rANS states; 5 also finer bins on float rasters),
    /// 2 its older fast coding; 6 its compact range-coded coding (6–8 % smaller, 2–6×
    /// slower to decode); 7–9 try them all. `vtz info --stats` says which coding a file holds.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=9))]
    pub effort: Option<u8>,
    #[command(flatten)]
    pub format: common::InputFormat,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub json: common::Json,
    /// Cut a raster larger than N samples in either direction into tiles of at most N × N
    /// that encode on all cores and decode alone (0 = never). Default: rasters of more than
    /// 4096² samples (whatever their shape) are cut into tiles of about 1024 × 1024 samples
    #[arg(long, value_name = "N")]
    pub tile: Option<u32>,
    #[command(flatten)]
    pub threads: common::Threads,
    /// Point sets: the grid step positions snap to, in the CRS's units (default: the
    /// coarsest power of ten the coordinates are multiples of, so positions are lossless).
    #[arg(long, value_name = "R")]
    pub xy_resolution: Option<f64>,
    /// Point sets: the bound of one value column, NAME=E (repeatable; others take
    /// --max-error).
    #[arg(long, value_name = "NAME=E")]
    pub max_error_band: Vec<String>,
    /// LAS/LAZ input: keep only points of this classification (2 = ground).
    #[arg(long, value_name = "C")]
    pub class: Option<u8>,
    /// Encode this raster with the input as one point set, one value column per raster
    /// (same grid; repeatable): one site set, one bound per band (--max-error-band).
    #[arg(long, value_name = "RASTER")]
    pub band: Vec<PathBuf>,
    /// Point sets: the positions' CRS, EPSG:n (for inputs that do not carry one, or to
    /// replace it).
    #[arg(long, value_name = "EPSG:n")]
    pub crs: Option<String>,
    #[command(flatten)]
    pub raster: RasterOpts,
}

/// `-o s3://bucket/key`: the output becomes a local temporary file, uploaded once the
/// command has written it and before it prints its summary ([`common::Staged::upload`]).
pub fn stage(a: &mut Args) -> Result<()> {
    let Some(url) = a
        .output
        .as_deref()
        .and_then(common::url_of)
        .map(str::to_string)
    else {
        return Ok(());
    };
    let staged = common::Staged::new(&url, a.force.force)?;
    a.output = Some(staged.local.clone());
    a.shown_output = Some(PathBuf::from(url));
    a.staged = Some(Box::new(staged));
    Ok(())
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let format = a.format.get()?;
    let bound = a.bound.get()?;
    let output = a
        .output
        .clone()
        .unwrap_or_else(|| common::default_output(&a.input, "vtz"));
    common::check_output(&a.input, &output, a.force.force)?;
    // Every option is parsed and checked before the (maybe long) read.
    let norm: vtz::Norm = a.norm.parse()?;
    let methods = vtz::Method::parse_list(&a.method)?;
    let rmse = a
        .rmse
        .as_deref()
        .map(|s| common::bound("--rmse", s))
        .transpose()?;
    if let Some(b) = a.bps.filter(|b| !(*b > 0.0 && b.is_finite())) {
        return Err(vtz::Error::invalid(format!("--bps {b} must be positive")));
    }
    let mut src = ui.busy("reading", || {
        common::open_source(&a.input, format, &a.raster)
    })?;
    for n in src.notes() {
        ui.say(format!("note: {n}"));
    }
    let samples = src.width() * src.height();
    let target_bytes = match (a.size, a.bps) {
        (Some(s), _) => Some(s),
        (None, Some(b)) if b > 0.0 && b.is_finite() => {
            Some((b * samples as f64 / 8.0).floor() as u64)
        }
        (None, Some(b)) => {
            return Err(vtz::Error::invalid(format!("--bps {b} must be positive")));
        }
        (None, None) => None,
    };
    let mut opts = EncodeOptions::default();
    opts.max_error = bound;
    opts.methods = methods;
    opts.params.sibson.rmse = rmse;
    if opts.params.sibson.rmse.is_some_and(|r| match r {
        ErrorBound::Abs(v) => v == 0.0,
        ErrorBound::PercentOfRange(p) => p == 0.0,
    }) {
        return Err(vtz::Error::invalid(
            "--rmse 0 asks the sites to reproduce every sample, which costs more than storing \
             them: use --lossless",
        ));
    }
    opts.params.sibson.sites = a.sites;
    opts.params.sibson.norm = norm;
    opts.params.sibson.step_factor = a.step_factor;
    opts.params.fis.k = a.fis_k;
    opts.params.fis.s = a.fis_s;
    opts.target_bytes = target_bytes;
    opts.effort = a.effort;
    opts.tile = a.tile;
    opts.threads = a.threads.threads;
    let mut out = vtz::formats::PendingFile::create(&output, a.force.force)?;
    let tiles = vtz::tile_count(src.width(), src.height(), &opts);
    let (_, report) = ui.progress_tiles("encoding", tiles, |p| {
        vtz::encode_stream(&mut *src, &opts, out.writer(), &mut |f| p(f))
    })?;
    drop(src);
    out.commit()?;
    if let Some(s) = &a.staged {
        s.upload(ui)?;
    }
    let info = vtz::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&output)
            .map_err(|e| vtz::Error::io(output.display().to_string(), e))?,
    ))?
    .info()
    .clone();
    let n = info.file_bytes;
    for (m, why) in &report.skipped {
        ui.say(format!("note: no {} section: {why}", m.name()));
    }
    for n in &report.notes {
        ui.say(format!("note: {n}"));
    }
    let raw = samples as u64 * info.sample_type.bits() as u64 / 8;
    // What any file pays whatever its samples: header, directory, checksums,
    // georeferencing and a method's own header (177 bytes for a georeferenced 1 × 1 raster).
    const FRAMING: u64 = 512;
    if n > raw && !a.json.json {
        if n <= raw + FRAMING {
            // Nothing to suggest: no method or bound makes so few samples smaller.
            ui.say(format!(
                "note: {n} bytes is more than the raw samples ({raw} bytes): the header, \
                 directory and checksums outweigh so few samples"
            ));
        } else if report.max_error > 0.0 {
            ui.say(format!(
                "warning: {n} bytes is more than the raw samples ({raw} bytes); --lossless or another --method may store this raster smaller"
            ));
        } else {
            ui.say(format!(
                "warning: {n} bytes is more than the raw samples ({raw} bytes): these samples \
                 do not compress losslessly"
            ));
        }
    }
    let bps = vtz::metrics::bits_per_sample(n, samples);
    let range = info.range.map_or(0.0, |(lo, hi)| hi - lo);
    let pct = if range > 0.0 {
        100.0 * report.max_error / range
    } else {
        0.0
    };
    let sites = report.stats.as_ref().and_then(|s| s.count("sites"));
    let stat = |k: &str| report.stats.as_ref().and_then(|s| s.get(k).cloned());
    if a.json.json {
        let j = serde_json::json!({
            "input": a.input, "output": a.shown_output.as_ref().unwrap_or(&output), "bytes": n, "samples": samples,
            "tiles": info.tiles.as_ref().map_or(1, |t| t.tiles.len()),
            "bits_per_sample": bps,
            "ratio": info.sample_type.bits() as f64 / bps.max(f64::MIN_POSITIVE),
            "max_error": report.max_error, "max_error_pct": pct,
            "lossless": report.max_error == 0.0,
            "method": report.method.name(),
            "value_scale": info.mapping.scale, "value_offset": info.mapping.offset,
            "output_type": crate::info::output_json(
                vtz::OutputType::of(info.sample_type, info.mapping, info.nodata)),
            "encoded": report.encoded.iter().map(|m| m.name()).collect::<Vec<_>>(),
            "skipped": report.skipped.iter().map(|(m, why)| serde_json::json!({"method": m.name(), "reason": why})).collect::<Vec<_>>(),
            "notes": report.notes,
            "sites": sites,
            "levels": stat("levels").map(common::stat_json),
            "position_bits_per_site": stat("position_bits_per_site").map(common::stat_json),
            "height_bits_per_site": stat("height_bits_per_site").map(common::stat_json),
        });
        outln!("{j}");
    } else {
        let what = if report.max_error == 0.0 && sites.is_none() {
            "lossless".to_string()
        } else {
            format!(
                "max error ≤ {} ({} % of range)",
                num(report.max_error),
                num(pct)
            )
        };
        let levels = match stat("levels") {
            Some(vtz::StatValue::Counts(l)) => l.len(),
            _ => 0,
        };
        let what = match sites {
            Some(n) => format!("{what}, {n} sites in {levels} levels"),
            None => format!("{what}, {}", report.method.name()),
        };
        ui.say(format!(
            "{}: {n} bytes, {bps:.3} bits/sample ({:.1}:1 against {}), {what}",
            a.shown_output.as_ref().unwrap_or(&output).display(),
            info.sample_type.bits() as f64 / bps.max(f64::MIN_POSITIVE),
            info.sample_type.name()
        ));
        if !info.mapping.is_identity() {
            // A GDAL scale/offset or a PNG's mapping: the bound is on the values.
            ui.say(format!(
                "  values = {} + {} * code ({} codes): the max error is in values; GDAL reads {}",
                info.mapping.offset,
                info.mapping.scale,
                info.sample_type.name(),
                vtz::OutputType::of(info.sample_type, info.mapping, info.nodata).describe()
            ));
        }
        if let Some(t) = &info.tiles {
            ui.say(format!(
                "  {} of {}x{} ({} x {})",
                common::count(t.tiles.len() as u64, "tile"),
                t.tile_width,
                t.tile_height,
                t.cols,
                t.rows
            ));
        }
    }
    Ok(())
}
