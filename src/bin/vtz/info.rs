//! `vtz info`: print a .vtz file's header and section directory.

use crate::common::{self, Ui};
use std::path::PathBuf;
use vtz::metrics::num;
use vtz::{Limits, RasterType, Result};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print JSON on stdout instead of text")))]
pub struct Args {
    /// Input .vtz file: a path, or a URL (https://…, http://…, s3://bucket/key).
    pub input: PathBuf,
    #[command(flatten)]
    pub json: common::Json,
    /// Also decode the sections' parameters: sites, levels, bits per site, L∞ and RMSE of a
    /// sites section; k, points and factors of an FIS section; levels of a Haar section.
    #[arg(long)]
    pub stats: bool,
    /// Tiled files: list every tile (position, size, bytes, method, max error).
    #[arg(long)]
    pub tiles: bool,
}

pub fn run(a: Args, _ui: &Ui) -> Result<()> {
    let mut dec = common::open_decoder(&a.input, Limits::default())
        .map_err(|e| e.context(a.input.display()))?;
    let info = dec.info().clone();
    let h = &info;
    let samples = h.samples() as usize;
    let bps = vtz::metrics::bits_per_sample(info.file_bytes, samples);
    // The bound the file guarantees, read from the sections without decoding them.
    // `info` shows a damaged file's header too: a bound it cannot read is shown as such
    // (`vtz verify` is the check).
    let bounds = dec
        .section_max_errors()
        .unwrap_or_else(|_| vec![None; info.sections.len()]);
    let max_error = dec.max_error();
    let sections: Vec<_> = info
        .sections
        .iter()
        .zip(&bounds)
        .map(|(e, b)| {
            serde_json::json!({
                "index": e.index, "type": e.name, "code": e.code,
                "method": e.method.map(|m| m.name()),
                "required": e.required,
                "primary": e.primary,
                "offset": e.offset, "bytes": e.bytes,
                "bits_per_sample": vtz::metrics::bits_per_sample(e.bytes, samples),
                "max_error": b,
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
        dec.stats()?
    } else if info.tiles.is_none()
        && info
            .sections
            .iter()
            .any(|e| e.method == Some(vtz::Method::RESIDUAL))
    {
        // The residual layer's coding (predictor, levels, lattice step) is read from its
        // section's header: cheap, so plain `info` names it too.
        dec.method_stats(vtz::Method::RESIDUAL)?
            .into_iter()
            .collect()
    } else {
        Vec::new()
    };
    let tiles = info.tiles.as_ref().map(|t| {
        serde_json::json!({
            "tile_width": t.tile_width, "tile_height": t.tile_height,
            "cols": t.cols, "rows": t.rows, "count": t.tiles.len(), "margin": t.margin,
            "overview_split": t.overview_split,
            "head_bytes": t.tiles.iter().map(|e| e.head_bytes).sum::<u64>(),
            "index": t.tiles.iter().map(|e| serde_json::json!({
                "tile": e.index, "x": e.window.x, "y": e.window.y,
                "width": e.window.width, "height": e.window.height,
                "coded": [e.coded.x, e.coded.y, e.coded.width, e.coded.height],
                "offset": e.offset, "bytes": e.bytes, "head_bytes": e.head_bytes,
                "tail_offset": e.tail_offset, "method": e.method,
                "valid": e.valid, "min": e.range.map(|r| r.0), "max": e.range.map(|r| r.1),
                "max_error": e.max_error,
            })).collect::<Vec<_>>(),
        })
    });
    if a.json.json {
        let mut j = serde_json::json!({
            "file": a.input, "bytes": info.file_bytes, "width": h.width, "height": h.height,
            "samples": samples, "sample_type": h.sample_type.name(),
            "value_scale": h.mapping.scale, "value_offset": h.mapping.offset,
            "output_type": output_json(dec.output_type()),
            "nodata": h.nodata, "min": h.range.map(|r| r.0), "max": h.range.map(|r| r.1),
            "bits_per_sample": bps, "max_error": max_error.as_ref().ok(),
            "lossless": max_error.as_ref().ok().map(|&m| m == 0.0),
            "georef": georef, "sections": sections,
            "version": info.version, "tiles": tiles,
        });
        // One object per method with a section (grid has no statistics); the sibson
        // statistics keep their first key, "stats".
        for m in vtz::Method::all().filter(|m| m.has_stats()) {
            let key = if m == vtz::Method::SIBSON {
                "stats"
            } else {
                m.name()
            };
            j[key] = serde_json::Value::Null;
        }
        for st in &stats {
            if st.values.is_empty() {
                continue;
            }
            let key = if st.method == vtz::Method::SIBSON {
                "stats"
            } else {
                st.method.name()
            };
            let obj: serde_json::Map<String, serde_json::Value> = st
                .values
                .iter()
                .map(|(k, v)| (k.to_string(), common::stat_json(v.clone())))
                .collect();
            j[key] = serde_json::Value::Object(obj);
        }
        outln!("{}", serde_json::to_string_pretty(&j).unwrap_or_default());
        return Ok(());
    }
    outln!("file          {}", a.input.display());
    outln!(
        "size          {} x {} = {samples} samples, {}",
        h.width,
        h.height,
        h.sample_type.name()
    );
    outln!(
        "bytes         {} ({bps:.4} bits/sample, {:.2}:1 against {})",
        info.file_bytes,
        h.sample_type.bits() as f64 / bps,
        h.sample_type.name()
    );
    if let Some((lo, hi)) = h.range {
        outln!("range         {} .. {}", num(lo), num(hi));
    }
    if !h.mapping.is_identity() {
        outln!(
            "mapping       value = {} + {} * code ({} codes; range, nodata and max error are \
             in values)",
            h.mapping.offset,
            h.mapping.scale,
            h.sample_type.name()
        );
        outln!(
            "values as     {} (GDAL's band, a decoded GeoTIFF)",
            dec.output_type().describe()
        );
    }
    match h.nodata {
        Some(nd) => outln!("nodata        {}", num(nd)),
        None => outln!("nodata        none declared"),
    }
    let by = match &info.tiles {
        Some(_) => "the worst tile's".to_string(),
        None => info
            .sections
            .get(info.primary)
            .map_or_else(String::new, |e| format!("the {} section's", e.name)),
    };
    match &max_error {
        Ok(m) if *m == 0.0 => outln!("max error     0 (lossless)"),
        Ok(m) => outln!(
            "max error     {} on every valid sample ({by} stored bound)",
            num(*m)
        ),
        Err(e) => outln!("max error     unreadable ({e})"),
    }
    match &h.georef {
        Some(g) => {
            outln!(
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
            if let Some(c) = vtz::formats::crs_summary(g) {
                outln!("crs           {c}");
            }
            if g.geokeys.is_some() {
                outln!("geotiff keys  kept");
            }
        }
        None => outln!("georef        none"),
    }
    for st in &stats {
        for line in &st.lines {
            outln!("{line}");
        }
    }
    if let Some(t) = &info.tiles {
        let mut methods: Vec<(String, usize, u64)> = Vec::new();
        for e in &t.tiles {
            match methods.iter_mut().find(|m| m.0 == e.method) {
                Some(m) => {
                    m.1 += 1;
                    m.2 += e.bytes;
                }
                None => methods.push((e.method.clone(), 1, e.bytes)),
            }
        }
        let worst = t.tiles.iter().map(|e| e.max_error).fold(0.0, f64::max);
        outln!(
            "tiles         {} x {} = {} tiles of {} x {} (version {}), blended over {} samples, max error {}",
            t.cols,
            t.rows,
            t.tiles.len(),
            t.tile_width,
            t.tile_height,
            info.version,
            2 * t.margin,
            num(worst)
        );
        for (m, n, b) in &methods {
            outln!(
                "  {m:<9} {:>12} {b:>12} bytes",
                common::count(*n as u64, "tile")
            );
        }
        if let Some(k) = t.overview_split {
            let heads: u64 = t.tiles.iter().map(|e| e.head_bytes).sum();
            outln!(
                "  heads     overview {k} ({} x {}) and coarser in one range: {heads} bytes ({:.1} % of the file)",
                info.width.div_ceil(1 << k),
                info.height.div_ceil(1 << k),
                100.0 * heads as f64 / info.file_bytes.max(1) as f64
            );
        }
        if a.tiles {
            outln!("  tile      x      y  width height      bytes method     max error");
            for e in &t.tiles {
                outln!(
                    "  {:>4} {:>6} {:>6} {:>6} {:>6} {:>10} {:<9} {}",
                    e.index,
                    e.window.x,
                    e.window.y,
                    e.window.width,
                    e.window.height,
                    e.bytes,
                    e.method,
                    num(e.max_error)
                );
            }
        }
    }
    outln!("sections      {}", info.sections.len());
    // A method's section by the method's name (`sibson`, as --method takes it; the spec's
    // type name `sites` is its alias), the others by their type; one column for all.
    let name = |e: &vtz::SectionInfo| e.method.map_or(e.name.clone(), |m| m.name().to_string());
    let width = info
        .sections
        .iter()
        .map(|e| name(e).chars().count())
        .max()
        .unwrap_or(0)
        .max(9);
    let iw = info.sections.len().saturating_sub(1).to_string().len();
    for (e, b) in info.sections.iter().zip(&bounds) {
        outln!(
            "  [{:>iw$}] {:<width$} {:>10} bytes {:>8.4} bits/sample{}{}{}",
            e.index,
            name(e),
            e.bytes,
            vtz::metrics::bits_per_sample(e.bytes, samples),
            if e.primary { "  primary" } else { "" },
            if e.required { "  required" } else { "" },
            b.map_or_else(String::new, |b| format!("  max error {}", num(b)))
        );
    }
    Ok(())
}

/// `vtz info --json`'s `output_type`: the type GDAL's band and a decoded GeoTIFF hold, and
/// the band offset and scale when it holds codes (else null).
pub(crate) fn output_json(t: vtz::OutputType) -> serde_json::Value {
    let m = t.offset_scale();
    serde_json::json!({
        "type": t.sample_type().name(),
        "offset": m.map(|m| m.offset),
        "scale": m.map(|m| m.scale),
    })
}
