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
    if a.json {
        let j = serde_json::json!({
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
