//! Terrain for web maps (`vtz web`): a raster as a raster-dem tile pyramid in the Web
//! Mercator XYZ scheme (EPSG:3857, y = 0 north), in one PMTiles v3 archive that MapLibre GL
//! JS reads by range requests.
//!
//! Each tile is `dim × dim` heights (256 or 512) with no border: MapLibre fills a tile's
//! border from its neighbours itself (`DEMData.backfillBorder`), and pixel (i, j) is the
//! cell centred at `(i + ½, j + ½)/dim` of the tile, as MapLibre places it (module
//! [`pyramid`]). The finest zoom is resampled from the source (bilinear, nodata kept;
//! geographic sources directly, projected ones through `proj4rs`); each coarser zoom is the
//! 2 × 2 mean of the one below.
//!
//! A tile of the default format is a complete `.vtz` stream (container version 1, the
//! residual layer's lane coding, float32 samples, a nodata mask where the tile has nodata,
//! no georeferencing: the archive places it) within the zoom's bound: by default a tenth of
//! the zoom's ground pixel size at the data's latitude farthest from the equator (where a
//! pixel is smallest), as [`WebRequest::pixel_fraction`] says. The browser decoder (`web/`)
//! turns it into heights and the RGBA MapLibre reads. The other formats write the same
//! pyramid in today's encodings (Terrarium, Terrain-RGB; the PNG reader's `RgbHeights`) for
//! comparison.

pub mod pyramid;
mod rgb;

use crate::error::{Error, Result};
use crate::formats::png::RgbHeights;
use crate::model::{Raster, SampleType};
use crate::quant::ErrorBound;
use crate::{Encoder, Method};
use pyramid::{Level, Source};
use rayon::prelude::*;
use rgb::ImageFormat;
use std::io::{Seek, Write};
use std::path::Path;

/// What each tile of the archive holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileFormat {
    /// A `.vtz` stream within the zoom's bound (PMTiles tile type 0, "other").
    Vtz,
    /// Terrarium heights in an RGB PNG.
    TerrariumPng,
    /// Terrarium heights in a lossless RGB WebP.
    TerrariumWebp,
    /// Mapbox Terrain-RGB heights in an RGB PNG.
    MapboxPng,
    /// The resampled heights themselves, uncompressed little-endian float32 (NaN =
    /// nodata): the pyramid other codecs are measured on (PMTiles tile type 0).
    F32,
}

impl TileFormat {
    /// The names `vtz web --format` takes.
    pub const NAMES: [&'static str; 5] = [
        "vtz",
        "terrarium-png",
        "terrarium-webp",
        "mapbox-png",
        "f32",
    ];

    /// The format of a `--format` name.
    pub fn parse(s: &str) -> Result<TileFormat> {
        Ok(match s {
            "vtz" => TileFormat::Vtz,
            "terrarium-png" => TileFormat::TerrariumPng,
            "terrarium-webp" => TileFormat::TerrariumWebp,
            "mapbox-png" => TileFormat::MapboxPng,
            "f32" => TileFormat::F32,
            _ => {
                return Err(Error::invalid(format!(
                    "--format must be one of {}, not '{s}'",
                    TileFormat::NAMES.join(", ")
                )));
            }
        })
    }

    /// Its `--format` name.
    pub fn name(self) -> &'static str {
        match self {
            TileFormat::Vtz => "vtz",
            TileFormat::TerrariumPng => "terrarium-png",
            TileFormat::TerrariumWebp => "terrarium-webp",
            TileFormat::MapboxPng => "mapbox-png",
            TileFormat::F32 => "f32",
        }
    }

    fn rgb(self) -> Option<(RgbHeights, ImageFormat)> {
        match self {
            TileFormat::Vtz | TileFormat::F32 => None,
            TileFormat::TerrariumPng => Some((RgbHeights::Terrarium, ImageFormat::Png)),
            TileFormat::TerrariumWebp => Some((RgbHeights::Terrarium, ImageFormat::Webp)),
            TileFormat::MapboxPng => Some((RgbHeights::TerrainRgb, ImageFormat::Png)),
        }
    }

    /// The MapLibre `raster-dem` encoding a map gives the decoded tiles.
    fn encoding(self) -> &'static str {
        match self {
            TileFormat::Vtz => "vtz",
            TileFormat::TerrariumPng | TileFormat::TerrariumWebp => "terrarium",
            TileFormat::MapboxPng => "mapbox",
            TileFormat::F32 => "float32",
        }
    }
}

/// What `vtz web` asks for.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct WebRequest {
    /// The tiles' content.
    pub format: TileFormat,
    /// Pixels a tile side: 256 or 512.
    pub tile_size: u32,
    /// The bound of every zoom in metres (vtz tiles only); `None` = `pixel_fraction` of the
    /// zoom's ground pixel size.
    pub max_error: Option<f64>,
    /// Without `max_error`, each zoom's bound is this fraction of its ground pixel size at
    /// the data's latitude farthest from the equator (default 0.1).
    pub pixel_fraction: f64,
    /// The coarsest zoom written (default 0).
    pub min_zoom: u8,
    /// The finest zoom (default: the first whose pixels are no larger than the source's).
    pub max_zoom: Option<u8>,
    /// Encoder effort of the vtz tiles (default: the codec's default, the lane coding).
    pub effort: Option<u8>,
    /// The archive's name in its metadata.
    pub name: String,
    /// Beside the archive, `{z}/{x}/{y}.f32` holding each vtz tile as the Rust decoder
    /// decodes it (little-endian float32, NaN = nodata): for checking another decoder.
    pub expected_dir: Option<std::path::PathBuf>,
}

impl WebRequest {
    /// Refuse a request no archive can satisfy (a usage error).
    pub fn validate(&self) -> Result<()> {
        if self.tile_size != 256 && self.tile_size != 512 {
            return Err(Error::invalid(format!(
                "--tile-size must be 256 or 512 (the sizes MapLibre's raster-dem sources take), not {}",
                self.tile_size
            )));
        }
        if !(self.pixel_fraction.is_finite() && self.pixel_fraction > 0.0) {
            return Err(Error::invalid(format!(
                "--pixel-fraction must be a number > 0, not {}",
                self.pixel_fraction
            )));
        }
        if let Some(e) = self.max_error
            && !(e.is_finite() && e >= 0.0)
        {
            return Err(Error::invalid(format!(
                "--max-error must be a number of metres ≥ 0, not {e}"
            )));
        }
        if self.max_zoom.is_some_and(|z| z > pyramid::MAX_ZOOM) {
            return Err(Error::invalid(format!(
                "--max-zoom must be at most {}",
                pyramid::MAX_ZOOM
            )));
        }
        if let Some(z) = self.max_zoom
            && self.min_zoom > z
        {
            return Err(Error::invalid(format!(
                "--min-zoom {} is above --max-zoom {z}",
                self.min_zoom
            )));
        }
        Ok(())
    }
}

impl Default for WebRequest {
    fn default() -> Self {
        WebRequest {
            format: TileFormat::Vtz,
            tile_size: 512,
            max_error: None,
            pixel_fraction: 0.1,
            min_zoom: 0,
            max_zoom: None,
            effort: None,
            name: "vtz terrain".into(),
            expected_dir: None,
        }
    }
}

/// One zoom of a written archive.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct WebLevel {
    /// Zoom.
    pub zoom: u8,
    /// Tiles written (tiles with no valid pixel are left out).
    pub tiles: usize,
    /// Bytes of those tiles (before PMTiles' deduplication of identical tiles).
    pub bytes: u64,
    /// The bound of the zoom's heights (metres): vtz tiles meet it; RGB tiles have their
    /// encoding's half step.
    pub bound: f64,
    /// Ground pixel size of the zoom at the latitude the bound was taken at (metres).
    pub pixel_metres: f64,
    /// Largest |decoded − resampled| over every valid pixel of the zoom, measured on the
    /// tiles as a decoder reads them (vtz: the Rust decoder; RGB: the unpacked codes).
    pub max_error: f64,
    /// Valid pixels measured.
    pub samples: u64,
}

/// What [`write_web`] wrote.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct WebReport {
    /// One entry per zoom, coarsest first.
    pub levels: Vec<WebLevel>,
    /// The archive's size in bytes.
    pub bytes: u64,
    /// Longitude/latitude bounds of the data: west, south, east, north (degrees).
    pub bounds: [f64; 4],
    /// Pixels a tile side.
    pub tile_size: u32,
}

impl WebReport {
    /// Tiles over all zooms.
    pub fn tiles(&self) -> usize {
        self.levels.iter().map(|l| l.tiles).sum()
    }
}

/// Write `raster` as a raster-dem pyramid in a PMTiles archive at `path` (atomically: a
/// temporary sibling renamed into place), refusing an existing file unless `force`.
/// `progress` gets the fraction done.
///
/// Errors: no georeferencing, a CRS vtz cannot transform, a tile size other than 256/512,
/// a zoom that would not fit in memory, I/O.
pub fn write_web(
    raster: &Raster,
    req: &WebRequest,
    path: &Path,
    force: bool,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<WebReport> {
    let mut file = crate::formats::PendingFile::create(path, force)?;
    let report = write_web_to(raster, req, file.writer(), progress)?;
    file.commit()?;
    Ok(report)
}

/// [`write_web`] into any seekable writer.
pub fn write_web_to<W: Write + Seek>(
    raster: &Raster,
    req: &WebRequest,
    out: W,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<WebReport> {
    req.validate()?;
    let src = Source::new(raster)?;
    let dim = req.tile_size;
    let max_zoom = match req.max_zoom {
        Some(z) => z,
        None => pyramid::default_max_zoom(&src, dim),
    };
    if req.min_zoom > max_zoom {
        return Err(Error::invalid(format!(
            "--min-zoom {} is above the finest zoom {max_zoom}",
            req.min_zoom
        )));
    }
    // The bound's latitude: the data's farthest from the equator, where pixels are smallest.
    let lat = src.bounds[1].abs().max(src.bounds[3].abs());
    let zooms = u32::from(max_zoom - req.min_zoom) + 1;
    // Progress: resampling the finest zoom is the first fifth, the zooms' tiles the rest
    // (each zoom has about a quarter of the tiles of the one below).
    let weight = |z: u8| 0.25f64.powi(i32::from(max_zoom - z));
    let total: f64 = (req.min_zoom..=max_zoom).map(weight).sum();
    let done = std::sync::Mutex::new(0.0f64);
    let mut level = pyramid::finest_level(&src, max_zoom, dim, &|f| progress(0.2 * f))?;
    let mut tiles: Vec<(u64, pmtiles::TileCoord, Vec<u8>)> = Vec::new();
    let mut levels = Vec::with_capacity(zooms as usize);
    loop {
        let z = level.zoom;
        let pixel_metres = pyramid::ground_resolution(z, dim, lat);
        let bound = req.max_error.unwrap_or(req.pixel_fraction * pixel_metres);
        let zoom_tiles = level.tiles();
        let n = zoom_tiles.len().max(1) as f64;
        let counter = std::sync::atomic::AtomicUsize::new(0);
        let base = *done.lock().unwrap_or_else(|e| e.into_inner());
        let encoded: Vec<Result<Tile>> = zoom_tiles
            .par_iter()
            .map(|&(x, y)| {
                let r = encode_tile(&level, x, y, req, bound);
                let k = counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress(0.2 + 0.8 * (base + weight(z) * k as f64 / n) / total);
                r
            })
            .collect();
        *done.lock().unwrap_or_else(|e| e.into_inner()) += weight(z);
        let mut lv = WebLevel {
            zoom: z,
            bound: if req.format == TileFormat::Vtz {
                bound
            } else {
                0.0
            },
            pixel_metres,
            ..WebLevel::default()
        };
        for r in encoded {
            let (x, y, bytes, err, samples) = r?;
            lv.tiles += 1;
            lv.bytes += bytes.len() as u64;
            lv.max_error = lv.max_error.max(err);
            lv.samples += samples;
            let coord = pmtiles::TileCoord::new(z, x, y)
                .map_err(|e| Error::invalid(format!("tile {z}/{x}/{y}: {e}")))?;
            if let Some(dir) = &req.expected_dir {
                write_expected(dir, z, x, y, &bytes)?;
            }
            tiles.push((pmtiles::TileId::from(coord).value(), coord, bytes));
        }
        if let Some((enc, _)) = req.format.rgb() {
            lv.bound = match enc {
                RgbHeights::Terrarium => 1.0 / 512.0,
                RgbHeights::TerrainRgb => 0.05,
            };
        }
        levels.push(lv);
        if z == req.min_zoom {
            break;
        }
        level = level.coarser();
    }
    levels.reverse();
    tiles.sort_by_key(|t| t.0);
    let bounds = src.bounds;
    let metadata = metadata(req, &levels, bounds, max_zoom);
    let tile_type = match req.format {
        TileFormat::Vtz | TileFormat::F32 => pmtiles::TileType::Unknown,
        TileFormat::TerrariumPng | TileFormat::MapboxPng => pmtiles::TileType::Png,
        TileFormat::TerrariumWebp => pmtiles::TileType::Webp,
    };
    let centre_zoom = req.min_zoom.max(max_zoom.saturating_sub(2));
    let mut out = out;
    let pm = |e: pmtiles::PmtError| Error::invalid(format!("writing the PMTiles archive: {e}"));
    let mut w = pmtiles::PmTilesWriter::new(tile_type)
        .tile_compression(pmtiles::Compression::None)
        .min_zoom(req.min_zoom)
        .max_zoom(max_zoom)
        .bounds(bounds[0], bounds[1], bounds[2], bounds[3])
        .center(0.5 * (bounds[0] + bounds[2]), 0.5 * (bounds[1] + bounds[3]))
        .center_zoom(centre_zoom)
        .metadata(metadata.to_string())
        .create(&mut out)
        .map_err(pm)?;
    for (_, coord, bytes) in &tiles {
        w.add_tile(*coord, bytes).map_err(pm)?;
    }
    w.finalize().map_err(pm)?;
    let bytes = out
        .seek(std::io::SeekFrom::End(0))
        .map_err(|e| Error::io("writing the PMTiles archive", e))?;
    progress(1.0);
    Ok(WebReport {
        levels,
        bytes,
        bounds,
        tile_size: dim,
    })
}

/// An encoded tile: (x, y, bytes, max |decoded − level|, valid pixels).
type Tile = (u32, u32, Vec<u8>, f64, u64);

/// Encode tile (x, y) of `level`.
fn encode_tile(level: &Level, x: u32, y: u32, req: &WebRequest, bound: f64) -> Result<Tile> {
    let heights = level.tile(x, y);
    let dim = req.tile_size;
    let valid = heights.iter().filter(|v| !v.is_nan()).count() as u64;
    let ctx = |e: Error| e.context(format!("tile {}/{x}/{y}", level.zoom));
    if let Some((enc, img)) = req.format.rgb() {
        let rgb = rgb::pack(enc, &heights);
        let err = heights
            .iter()
            .filter(|h| !h.is_nan())
            .map(|&h| (rgb::height(enc, rgb::code(enc, h)) - f64::from(h)).abs())
            .fold(0.0, f64::max);
        let bytes = rgb::encode_image(&rgb, dim, img).map_err(ctx)?;
        return Ok((x, y, bytes, err, valid));
    }
    if req.format == TileFormat::F32 {
        let bytes = heights.iter().flat_map(|h| h.to_le_bytes()).collect();
        return Ok((x, y, bytes, 0.0, valid));
    }
    let data: Vec<f64> = heights.iter().map(|&h| f64::from(h)).collect();
    let d = dim as usize;
    let raster = Raster::from_values(d, d, data, None, SampleType::F32).map_err(ctx)?;
    let mut enc = Encoder::new()
        .max_error(ErrorBound::Abs(bound))
        .method(Method::RESIDUAL);
    enc.options_mut().effort = req.effort;
    enc.options_mut().tile = Some(0);
    let bytes = enc.encode(&raster).map_err(ctx)?;
    // Measured on the tile as a decoder reads it (the encoder checked it too).
    let back = crate::decode(&bytes).map_err(ctx)?;
    let mut err = 0.0f64;
    for (i, &h) in heights.iter().enumerate() {
        let ok = back.is_valid(i);
        if ok == h.is_nan() {
            return Err(ctx(Error::corrupt(format!(
                "pixel {i}'s nodata did not survive the round trip"
            ))));
        }
        if ok {
            err = err.max((back.data[i] - f64::from(h)).abs());
        }
    }
    if err > bound {
        return Err(ctx(Error::corrupt(format!(
            "decoded error {err} is over the bound {bound}"
        ))));
    }
    Ok((x, y, bytes, err, valid))
}

fn write_expected(dir: &Path, z: u8, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
    let r = crate::decode(bytes)?;
    let mut out = Vec::with_capacity(r.len() * 4);
    for i in 0..r.len() {
        let v = if r.is_valid(i) {
            r.data[i] as f32
        } else {
            f32::NAN
        };
        out.extend_from_slice(&v.to_le_bytes());
    }
    let d = dir.join(z.to_string()).join(x.to_string());
    std::fs::create_dir_all(&d).map_err(|e| Error::io(format!("creating {}", d.display()), e))?;
    let p = d.join(format!("{y}.f32"));
    std::fs::write(&p, out).map_err(|e| Error::io(format!("writing {}", p.display()), e))
}

/// The archive's JSON metadata: TileJSON-like keys MapLibre users know, and `vtz` with
/// what a decoder needs.
fn metadata(
    req: &WebRequest,
    levels: &[WebLevel],
    bounds: [f64; 4],
    max_zoom: u8,
) -> serde_json::Value {
    let format = match req.format {
        TileFormat::Vtz => "vtz",
        TileFormat::F32 => "f32",
        TileFormat::TerrariumPng | TileFormat::MapboxPng => "png",
        TileFormat::TerrariumWebp => "webp",
    };
    let mut m = serde_json::json!({
        "name": req.name,
        "description": "raster-dem terrain tiles (elevation in metres) written by vtz web",
        "type": "baselayer",
        "version": "1",
        "format": format,
        "encoding": req.format.encoding(),
        "tileSize": req.tile_size,
        "minzoom": req.min_zoom,
        "maxzoom": max_zoom,
        "bounds": bounds,
        "generator": concat!("vtz ", env!("CARGO_PKG_VERSION")),
    });
    if req.format == TileFormat::Vtz {
        m["vtz"] = serde_json::json!({
            "tile_format": "vtz container version 1, float32 heights in metres, NaN = nodata",
            "max_error": levels.iter().map(|l| serde_json::json!({
                "zoom": l.zoom, "bound": l.bound, "measured": l.max_error,
            })).collect::<Vec<_>>(),
            "pixel_fraction": if req.max_error.is_none() { Some(req.pixel_fraction) } else { None },
            "rgba": {"encoding": "terrarium"},
        });
    }
    m
}
