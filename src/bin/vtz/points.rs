//! Point sets in `vtz encode`, `vtz decode` and `vtz info`: scattered XYZ/CSV/LAS/LAZ points,
//! and rasters encoded as one point set with one value column per band (`--band`).

use crate::common::{self, Ui};
use crate::{decode, encode, info};
use vtz::formats::points::{
    PointFormat, ReadPointsOptions, WritePointsOptions, is_points_path, read_points_report,
    write_points,
};
use vtz::metrics::num;
use vtz::{Error, ErrorBound, PointSet, PointsOptions, Result};

/// Whether `vtz encode` takes this input as a point set.
pub fn is_points_input(a: &encode::Args) -> bool {
    is_points_path(&a.input) || !a.band.is_empty()
}

/// Reject raster-only options for a point set, and point-only options for a raster.
pub fn check_encode_options(a: &encode::Args) -> Result<()> {
    let points = is_points_input(a);
    if points {
        for (set, name) in [
            (a.lossless, "--lossless"),
            (a.bps.is_some(), "--bps"),
            (a.size.is_some(), "--size"),
            (a.sites.is_some(), "--sites"),
            (a.rmse.is_some(), "--rmse"),
            (a.fis_k.is_some() || a.fis_s.is_some(), "--fis-k/--fis-s"),
            (a.tile.is_some(), "--tile"),
            (a.method != "best", "--method"),
        ] {
            if set {
                return Err(Error::invalid(format!(
                    "{name} is for rasters; a point set takes --max-error, --max-error-band, --xy-resolution and --class"
                )));
            }
        }
    } else {
        for (set, name) in [
            (a.xy_resolution.is_some(), "--xy-resolution"),
            (!a.max_error_band.is_empty(), "--max-error-band"),
            (a.class.is_some(), "--class"),
            (a.crs.is_some(), "--crs"),
        ] {
            if set {
                return Err(Error::invalid(format!(
                    "{name} is for point sets (.xyz .csv .txt .las .laz input, or --band)"
                )));
            }
        }
    }
    if let Some(out) = &a.output {
        common::check_vtz_name(out)?;
    }
    Ok(())
}

/// A raster and its `--band` rasters as one point set ([`vtz::bands_to_points`]).
fn bands_as_points(a: &encode::Args, ui: &Ui) -> Result<PointSet> {
    let mut files = vec![a.input.clone()];
    files.extend(a.band.iter().cloned());
    let format = a.format.get()?;
    let mut bands = Vec::new();
    for f in files {
        let r = common::read_raster(&f, format, &a.raster).map_err(|e| e.context(f.display()))?;
        bands.push((f, r));
    }
    let (p, dropped) = vtz::bands_to_points(&bands)?;
    if dropped > 0 {
        ui.say(format!(
            "note: {dropped} samples valid in some bands but not all are left out (a point set holds every column at every point)"
        ));
    }
    Ok(p)
}

/// Parse `--max-error-band NAME=E`.
fn band_bounds(a: &encode::Args) -> Result<Vec<(String, ErrorBound)>> {
    a.max_error_band
        .iter()
        .map(|s| {
            let (n, e) = s.split_once('=').ok_or_else(|| {
                Error::invalid(format!(
                    "--max-error-band '{s}' is not NAME=E (e.g. dtm=0.05)"
                ))
            })?;
            Ok((n.trim().to_string(), ErrorBound::parse(e)?))
        })
        .collect()
}

/// `vtz encode` of a point set.
pub fn encode(a: &encode::Args, ui: &Ui) -> Result<()> {
    check_encode_options(a)?;
    let bound = a.bound.get()?.unwrap_or(ErrorBound::PercentOfRange(1.0));
    let bands = band_bounds(a)?;
    let crs = a.crs.as_deref().map(parse_crs).transpose()?;
    if let Some(r) = a.xy_resolution.filter(|r| !(*r > 0.0 && r.is_finite())) {
        return Err(Error::invalid(format!(
            "--xy-resolution {r} must be positive"
        )));
    }
    let output = a
        .output
        .clone()
        .unwrap_or_else(|| common::default_output(&a.input, "vtz"));
    common::check_output(&a.input, &output, a.force.force)?;
    let mut points = if a.band.is_empty() {
        let ro = ReadPointsOptions {
            class: a.class,
            ..Default::default()
        };
        let (ps, rep) = ui
            .busy("reading", || read_points_report(&a.input, &ro))
            .map_err(|e| e.context(a.input.display()))?;
        if let Some(n) = rep.note {
            ui.say(format!("note: {}: {n}", a.input.display()));
        }
        ps
    } else {
        if a.class.is_some() {
            return Err(Error::invalid("--class is for LAS/LAZ input"));
        }
        bands_as_points(a, ui)?
    };
    if let Some(n) = crs {
        points.epsg = Some(n);
        points.wkt = None;
    }
    let mut o = PointsOptions::new(bound);
    o.resolution = a.xy_resolution;
    o.bounds = bands;
    let (bytes, rep) = ui.progress("encoding", |p| {
        vtz::encode_points(&points, &o, &mut |f| p(f))
    })?;
    vtz::formats::write_file(&output, bytes, a.force.force)?;
    if let Some(s) = &a.staged {
        s.upload(ui)?;
    }
    if a.bound.max_error.is_none() {
        ui.say("note: no --max-error given: 1% of each column's value range");
    }
    if !rep.positions_lossless {
        ui.say(format!(
            "note: positions rounded to the nearest {} (--xy-resolution); the bound holds at the rounded positions",
            num(rep.resolution)
        ));
    }
    let bpp = 8.0 * rep.bytes as f64 / rep.points.max(1) as f64;
    if a.json.json {
        let j = serde_json::json!({
            "input": a.input, "output": a.shown_output.as_ref().unwrap_or(&output), "bytes": rep.bytes, "points": rep.points,
            "positions": rep.positions, "sites": rep.sites, "levels": rep.levels,
            "bits_per_point": bpp, "resolution": rep.resolution,
            "positions_lossless": rep.positions_lossless,
            "position_bytes": rep.position_bytes, "site_bytes": rep.site_bytes,
            "columns": rep.columns,
        });
        outln!("{j}");
    } else {
        let cols: Vec<String> = rep
            .columns
            .iter()
            .map(|c| {
                format!(
                    "{} max error {} ≤ {} (RMSE {})",
                    c.name,
                    num(c.max_error),
                    num(c.bound),
                    num(c.rmse)
                )
            })
            .collect();
        ui.say(format!(
            "{}: {} bytes, {bpp:.2} bits/point, {} points ({} positions), {} sites in {} levels; {}",
            a.shown_output.as_ref().unwrap_or(&output).display(),
            rep.bytes,
            rep.points,
            rep.positions,
            rep.sites,
            rep.levels.len(),
            cols.join("; ")
        ));
    }
    Ok(())
}

/// Which way `vtz decode` goes, decided before any work: the output's format is checked
/// before the input is opened; a point-set file comes back as its bytes (decoded here), a
/// raster file as `None` (the raster decoder's), and a raster file to a points output is a
/// usage error.
pub fn decode_route(a: &decode::Args) -> Result<Option<Vec<u8>>> {
    let points_out = is_points_path(&a.output);
    if !points_out && a.format.is_none() {
        vtz::formats::Format::from_path(&a.output)?;
    }
    if common::is_points_file(&a.input)? {
        common::check_output(&a.input, &a.output, a.force.force)?;
        return common::read_file(&a.input).map(Some);
    }
    if points_out {
        // Only a file that opens as a raster is "a raster file": a truncated or foreign one
        // gets the decoder's own error (corrupt input, exit 1), as `vtz info` says it.
        common::open_decoder(&a.input, vtz::Limits::default())
            .map_err(|e| e.context(a.input.display()))?;
        return Err(Error::invalid(format!(
            "{} is a raster file: it decodes to a raster format (.tif, .png, .exr, .hgt, .asc, .f32), not to points",
            a.input.display()
        )));
    }
    Ok(None)
}

/// `vtz decode` of a point-set file.
pub fn decode(a: &decode::Args, bytes: &[u8], ui: &Ui) -> Result<()> {
    let ctx = |e: Error| e.context(a.input.display());
    if a.section.is_some() || a.sites.is_some() || a.window.is_some() || a.scale.is_some() {
        return Err(Error::invalid(
            "--section, --sites, --window and --scale are for rasters; a point set takes --level, --sites-only, --cell, --column, --crs",
        ));
    }
    if a.surface != "sibson" {
        return Err(Error::invalid(
            "a point set decodes through its sibson surface only",
        ));
    }
    if let Some(f) = PointFormat::from_path(&a.output) {
        if a.cell.is_some() {
            return Err(Error::invalid(
                "--cell is for raster output (.tif, .asc, …)",
            ));
        }
        let mut d = vtz::DecodePoints::new()
            .sites_only(a.sites_only)
            .level(a.level);
        d.limits = vtz::Limits::default();
        let mut p = ui
            .busy("decoding", || vtz::decode_points(bytes, &d))
            .map_err(ctx)?;
        apply_crs(&mut p.epsg, &mut p.wkt, a.crs.as_deref())?;
        let wo = WritePointsOptions {
            force: a.force.force,
            ..Default::default()
        };
        let rep = ui.busy("writing", || write_points(&a.output, &p, &wo))?;
        if let Some(n) = rep.note {
            ui.say(format!("note: {n}"));
        }
        ui.say(format!(
            "{}: {} {} ({:?})",
            a.output.display(),
            p.len(),
            if a.sites_only { "sites" } else { "points" },
            f
        ));
        return Ok(());
    }
    let Some(cell) = a.cell else {
        return Err(Error::invalid(
            "a point set decodes to points (.xyz .csv .las .laz), or to a raster with --cell C",
        ));
    };
    if a.sites_only || a.level.is_some() {
        return Err(Error::invalid(
            "--sites-only and --level are for point output",
        ));
    }
    let format = common::parse_format(a.format.as_deref())?;
    if format.is_none() {
        vtz::formats::Format::from_path(&a.output)?;
    }
    let o = vtz::RasterizePoints::new(cell)
        .column(a.column.clone())
        .only_positions(a.only_positions);
    let mut r = ui
        .busy("rasterizing", || vtz::rasterize_points(bytes, &o))
        .map_err(ctx)?;
    if let Some(g) = r.georef.as_mut() {
        apply_crs(&mut g.epsg, &mut g.wkt, a.crs.as_deref())?;
    }
    let wo = common::write_options(format, a.force.force, &a.raster, &a.output_opts);
    ui.busy("writing", || vtz::write_path(&r, &a.output, &wo))?;
    ui.say(format!(
        "{}: {}x{} f32, cells of {}",
        a.output.display(),
        r.width,
        r.height,
        num(cell)
    ));
    Ok(())
}

/// `--crs EPSG:n` (or `n`): set the output's CRS (replacing the file's).
fn apply_crs(epsg: &mut Option<u32>, wkt: &mut Option<String>, crs: Option<&str>) -> Result<()> {
    if let Some(s) = crs {
        *epsg = Some(parse_crs(s)?);
        *wkt = None;
    }
    Ok(())
}

/// `EPSG:n` or `n`.
fn parse_crs(s: &str) -> Result<u32> {
    let t = s.trim();
    let code = t
        .strip_prefix("EPSG:")
        .or_else(|| t.strip_prefix("epsg:"))
        .unwrap_or(t);
    code.parse()
        .map_err(|_| Error::invalid(format!("--crs '{s}' is not EPSG:n")))
}

/// `vtz info` of a point-set file.
pub fn info(a: &info::Args, bytes: &[u8]) -> Result<()> {
    let i = vtz::points_info(bytes, vtz::Limits::default())
        .map_err(|e| e.context(a.input.display()))?;
    let bpp = 8.0 * i.bytes as f64 / i.points.max(1) as f64;
    if a.json.json {
        let j = serde_json::json!({
            "kind": "points", "version": 3, "bytes": i.bytes, "points": i.points,
            "positions": i.positions, "sites": i.sites, "levels": i.levels,
            "bits_per_point": bpp, "resolution": i.resolution, "bounds": i.bounds,
            "epsg": i.epsg, "has_wkt": i.has_wkt, "columns": i.columns,
            "sections": i.sections.iter().map(|(n, b)| serde_json::json!({"type": n, "bytes": b})).collect::<Vec<_>>(),
        });
        outln!("{j}");
        return Ok(());
    }
    outln!("{}: vtz point set (format version 3)", a.input.display());
    outln!(
        "  {} points at {} positions, {} sites in {} levels, {} bytes ({bpp:.2} bits/point)",
        i.points,
        i.positions,
        i.sites,
        i.levels.len(),
        i.bytes
    );
    outln!(
        "  positions on a grid of {} over [{}, {}] × [{}, {}]{}",
        num(i.resolution),
        num(i.bounds[0]),
        num(i.bounds[2]),
        num(i.bounds[1]),
        num(i.bounds[3]),
        i.epsg.map_or(String::new(), |e| format!(", EPSG:{e}"))
    );
    for c in &i.columns {
        outln!(
            "  column {}: bound {}, max error {}, RMSE {}",
            c.name,
            num(c.bound),
            num(c.max_error),
            num(c.rmse)
        );
    }
    for (n, b) in &i.sections {
        outln!("  section {n}: {b} bytes");
    }
    Ok(())
}
