//! `vtz info`: print a .vtz file's header and section directory.

use crate::common::{self, Ui};
use std::path::PathBuf;
use vtz::{Limits, RasterType, Result};

#[derive(clap::Args)]
pub struct Args {
    /// Input .vtz file.
    pub input: PathBuf,
    /// Print JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also decode the sections' parameters: sites, levels, bits per site, L∞ and RMSE of a
    /// sites section; k, points and factors of an FIS section; levels of a Haar section.
    #[arg(long)]
    pub stats: bool,
}

pub fn run(a: Args, _ui: &Ui) -> Result<()> {
    let bytes = common::read_file(&a.input)?;
    let info = vtz::info(&bytes, Limits::default()).map_err(|e| e.context(a.input.display()))?;
    let h = &info.header;
    let samples = h.samples() as usize;
    let bps = vtz::metrics::bits_per_sample(info.file_bytes, samples);
    let sections: Vec<_> = info
        .sections
        .iter()
        .enumerate()
        .map(|(i, e)| {
            serde_json::json!({
                "index": i, "type": e.kind.name(), "code": e.kind.code(),
                "required": e.flags & vtz::container::SF_REQUIRED != 0,
                "primary": i == h.primary as usize,
                "offset": e.offset, "bytes": e.length,
                "bits_per_sample": vtz::metrics::bits_per_sample(e.length, samples),
            })
        })
        .collect();
    let georef = h.georef.as_ref().map(|g| {
        serde_json::json!({
            "origin": g.origin, "pixel_size": g.pixel_size,
            "raster_type": match g.raster_type { RasterType::Area => "area", RasterType::Point => "point" },
            "epsg": g.epsg, "wkt": g.wkt, "geotiff_keys": g.geokeys.is_some(),
        })
    });
    let stats = if a.stats {
        match vtz::sites_section(&bytes, Limits::default()) {
            Ok((hd, mask, payload)) => Some(vtz::sites::stats(&payload, &hd, mask.as_deref())?),
            Err(vtz::Error::InvalidArgument { .. }) => None,
            Err(e) => return Err(e),
        }
    } else {
        None
    };
    // FIS and Haar parameters, when the file has those sections.
    let fis =
        match vtz::section_payload(&bytes, vtz::container::SectionKind::Fis, Limits::default())? {
            Some((hd, p)) if a.stats => Some(vtz::fis::describe(&p, &hd)?),
            _ => None,
        };
    let haar =
        match vtz::section_payload(&bytes, vtz::container::SectionKind::Haar, Limits::default())? {
            Some((_, p)) if a.stats => Some(vtz::haar::describe(&p)?),
            _ => None,
        };
    let range = h.range.map_or(0.0, |(lo, hi)| hi - lo);
    let pct = |v: f64| if range > 0.0 { 100.0 * v / range } else { 0.0 };
    let stats_json = stats.as_ref().map(|s| {
        serde_json::json!({
            "sites": s.sites, "hull": s.hull, "levels": s.levels,
            "position_bits_per_site": s.position_bits / s.sites.max(1) as f64,
            "height_bits_per_site": s.height_bits / s.sites.max(1) as f64,
            "max_error": s.max_error, "max_error_pct": pct(s.max_error),
            "rmse": s.rmse, "rmse_pct": pct(s.rmse),
        })
    });
    if a.json {
        let j = serde_json::json!({
            "stats": stats_json,
            "fis": fis.map(|(k, points, s0, iterations)| serde_json::json!({
                "k": k, "points": points, "s0": s0, "iterations": iterations })),
            "haar": haar.map(|(levels, lattice_step)| serde_json::json!({
                "levels": levels, "lattice_step": lattice_step })),
            "file": a.input, "bytes": info.file_bytes, "width": h.width, "height": h.height,
            "samples": samples, "sample_type": h.sample_type.name(),
            "value_scale": h.mapping.scale, "value_offset": h.mapping.offset,
            "nodata": h.nodata, "min": h.range.map(|r| r.0), "max": h.range.map(|r| r.1),
            "bits_per_sample": bps, "georef": georef, "sections": sections,
        });
        println!("{}", serde_json::to_string_pretty(&j).unwrap_or_default());
        return Ok(());
    }
    println!("file          {}", a.input.display());
    println!(
        "size          {} x {} = {samples} samples, {}",
        h.width,
        h.height,
        h.sample_type.name()
    );
    println!(
        "bytes         {} ({bps:.4} bits/sample, {:.2}:1 against {})",
        info.file_bytes,
        h.sample_type.bits() as f64 / bps,
        h.sample_type.name()
    );
    if let Some((lo, hi)) = h.range {
        println!("range         {lo} .. {hi}");
    }
    if !h.mapping.is_identity() {
        println!(
            "mapping       value = {} + {} * code",
            h.mapping.offset, h.mapping.scale
        );
    }
    match h.nodata {
        Some(nd) => println!("nodata        {nd}"),
        None => println!("nodata        none declared"),
    }
    match &h.georef {
        Some(g) => {
            println!(
                "georef        origin ({}, {}) pixel {} x {} ({})",
                g.origin[0],
                g.origin[1],
                g.pixel_size[0],
                g.pixel_size[1],
                match g.raster_type {
                    RasterType::Area => "pixel is area",
                    RasterType::Point => "pixel is point",
                }
            );
            if let Some(e) = g.epsg {
                println!("crs           EPSG:{e}");
            }
            if g.geokeys.is_some() {
                println!("geotiff keys  kept");
            }
        }
        None => println!("georef        none"),
    }
    if let Some(s) = &stats {
        let n = s.sites.max(1) as f64;
        println!(
            "sites         {} in {} levels {:?}",
            s.sites,
            s.levels.len(),
            s.levels
        );
        println!(
            "bits/site     {:.2} positions + {:.2} heights = {:.2}",
            s.position_bits / n,
            s.height_bits / n,
            (s.position_bits + s.height_bits) / n
        );
        println!(
            "achieved      max error {} ({:.4} % of range), rmse {:.4} ({:.4} %)",
            s.max_error,
            pct(s.max_error),
            s.rmse,
            pct(s.rmse)
        );
    }
    if let Some((k, points, s0, iters)) = fis {
        println!(
            "fis           spacing k = {k}: {points} interpolation points, s0 {s0}, {iters} iterations"
        );
    }
    if let Some((levels, step)) = haar {
        println!("haar          {levels} levels, value lattice step {step}");
    }
    println!("sections      {}", info.sections.len());
    for (i, e) in info.sections.iter().enumerate() {
        println!(
            "  [{i}] {:<9} {:>10} bytes {:>8.4} bits/sample{}{}",
            e.kind.name(),
            e.length,
            vtz::metrics::bits_per_sample(e.length, samples),
            if i == h.primary as usize {
                "  primary"
            } else {
                ""
            },
            if e.flags & vtz::container::SF_REQUIRED != 0 {
                "  required"
            } else {
                ""
            }
        );
    }
    Ok(())
}
