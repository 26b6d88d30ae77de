//! Raster file formats: one file per format, each reading into a [`Raster`] and writing from
//! one; sidecars and atomic output beside them. Callers reach them through `vtz::read_path`
//! and `vtz::write_path` (the codec), which also read and write `.vtz`.
//!
//! Besides vtz's own sidecars, outputs get what GDAL reads where the format has no place for
//! georeferencing (module `pam`): `.asc` a `.prj` (module `crs`); PNG a world file and a PAM
//! `.aux.xml`; EXR a PAM `.aux.xml`; each also an `.aux.xml` for GDAL_METADATA.

pub(crate) mod asc;
pub(crate) mod crs;
pub(crate) mod exr;
pub(crate) mod geotiff;
pub(crate) mod hgt;
mod output;
mod pam;
pub(crate) mod png;
pub mod points;
pub(crate) mod raw;
mod samples;
mod sidecar;

use crate::error::{Error, Result};
use crate::model::{DEFAULT_MAX_SAMPLES, Raster, SampleType, ValueMapping};
pub use geotiff::StreamWriter as GeoTiffWriter;
pub use output::{
    OutputFile, PendingFile, remove_temporaries, track as track_temporary,
    untrack as untrack_temporary, write_file,
};
pub(crate) use output::{track, untrack};
pub(crate) use pam::{apply_gdal_mapping, with_offset_scale, without_statistics};
pub use png::PngMapping;
use std::path::Path;

/// The CRS of a georeference as GDAL's `OGRSpatialReference::SetFromUserInput` takes it
/// (what vtz writes into a PAM `<SRS>`): its WKT when known (its own, else EPSG's from
/// vtz's table), else `EPSG:n`, else the source's PROJ string; `None` without a CRS.
pub fn crs_user_input(g: &crate::model::Georef) -> Option<String> {
    crs::crs_user_input(g).map(|c| c.into_owned())
}

/// The CRS of a georeference in one line for people (`vtz info`), both parts of a compound
/// CRS: `EPSG:32611 + vertical EPSG:5703 (NAVD88 height)`; just `EPSG:n` without a vertical
/// part; `None` with neither an EPSG code nor a vertical CRS.
pub fn crs_summary(g: &crate::model::Georef) -> Option<String> {
    crs::crs_summary(g)
}

/// A GeoTIFF of `r` in memory, as `vtz decode -o X.tif` writes a raster (the same tags,
/// GeoTIFF keys included). The C ABI gives a 1 x 1 one to GDAL so that a CRS stored only as
/// GeoTIFF keys reads back exactly as from the source GeoTIFF.
pub fn geotiff_bytes(r: &Raster) -> Result<Vec<u8>> {
    geotiff::write(r)
}

/// The names `--format` takes, for messages.
const KNOWN_FORMATS: &str = "tif, png, terrain-rgb, terrarium, exr, hgt, asc, f32, vtz";

/// Raster file formats vtz reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Format {
    /// GeoTIFF (`.tif`, `.tiff`).
    GeoTiff,
    /// 16-bit greyscale PNG with a value mapping; Mapbox Terrain-RGB PNGs are read too.
    Png,
    /// Mapbox Terrain-RGB PNG (height = -10000 + (R·65536 + G·256 + B)·0.1).
    TerrainRgb,
    /// Terrarium PNG of Mapzen/AWS terrain tiles (height = (R·256 + G + B/256) - 32768).
    Terrarium,
    /// OpenEXR, one f32 channel.
    Exr,
    /// SRTM `.hgt` (big-endian i16, -32768 = void, georef from the name).
    Hgt,
    /// ESRI ASCII grid (`.asc`).
    Asc,
    /// Raw little-endian f32 (`NAME.f32`) with a `NAME.json` sidecar.
    RawF32,
    /// The vtz container itself.
    Vtz,
}

impl Format {
    /// Format from a file extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .unwrap_or_default();
        Format::from_name(&ext).map_err(|_| {
            Error::invalid(format!(
                "cannot tell the format of {} from its extension '{ext}' (use --format; known: {KNOWN_FORMATS})",
                path.display()
            ))
        })
    }

    /// Format from a name or extension as given by `--format`.
    pub fn from_name(name: &str) -> Result<Format> {
        Ok(match name.to_ascii_lowercase().as_str() {
            "tif" | "tiff" | "geotiff" | "gtiff" => Format::GeoTiff,
            "png" | "png16" => Format::Png,
            "terrain-rgb" | "terrainrgb" => Format::TerrainRgb,
            "terrarium" => Format::Terrarium,
            "exr" => Format::Exr,
            "hgt" => Format::Hgt,
            "asc" | "ascii" => Format::Asc,
            "f32" | "raw" => Format::RawF32,
            "vtz" => Format::Vtz,
            other => {
                return Err(Error::invalid(format!(
                    "unknown raster format '{other}' (known: {KNOWN_FORMATS})"
                )));
            }
        })
    }

    /// The format's name for people.
    pub fn name(self) -> &'static str {
        match self {
            Format::GeoTiff => "GeoTIFF",
            Format::Png => "PNG16",
            Format::TerrainRgb => "Terrain-RGB PNG",
            Format::Terrarium => "Terrarium PNG",
            Format::Exr => "OpenEXR",
            Format::Hgt => "SRTM hgt",
            Format::Asc => "ESRI ASCII grid",
            Format::RawF32 => "raw f32 + json",
            Format::Vtz => "vtz",
        }
    }
}

/// Options for reading rasters: `ReadOptions::default()`, then the `with_*` setters.
#[derive(Clone, Debug, Default)]
#[non_exhaustive]
pub struct ReadOptions {
    /// Force a format instead of guessing from the extension.
    pub format: Option<Format>,
    /// Value mapping for 16-bit PNG input (overrides a sidecar).
    pub png_mapping: Option<png::PngMapping>,
    /// Upper bound on samples a reader may allocate (defaults to 2^28, as [`crate::Limits`]).
    pub max_samples: Option<u64>,
}

impl ReadOptions {
    /// Read as `format` instead of guessing from the extension.
    pub fn with_format(mut self, format: Option<Format>) -> Self {
        self.format = format;
        self
    }
    /// Map 16-bit PNG codes to values with `mapping` (over a sidecar's).
    pub fn with_png_mapping(mut self, mapping: Option<png::PngMapping>) -> Self {
        self.png_mapping = mapping;
        self
    }
    /// Allocate at most `n` samples.
    pub fn with_max_samples(mut self, n: Option<u64>) -> Self {
        self.max_samples = n;
        self
    }
    /// The sample limit in force.
    pub fn max_samples(&self) -> u64 {
        self.max_samples.unwrap_or(DEFAULT_MAX_SAMPLES)
    }
}

/// Options for writing rasters: `WriteOptions::default()`, then the `with_*` setters.
#[derive(Clone, Debug, Default)]
#[non_exhaustive]
pub struct WriteOptions {
    /// Force a format instead of guessing from the extension.
    pub format: Option<Format>,
    /// Replace existing output files.
    pub force: bool,
    /// Value mapping for 16-bit PNG output (defaults to the raster's own mapping).
    pub png_mapping: Option<png::PngMapping>,
    /// Let a format that cannot hold the values exactly (16-bit PNG codes, Terrain-RGB)
    /// round them; without it such a write is refused.
    pub round: bool,
    /// Let a format that cannot place the raster (an `.hgt` whose name is not the tile's
    /// `[NS]dd[EW]ddd`) write it without its georeferencing; without it such a write is
    /// refused.
    pub drop_georef: bool,
}

impl WriteOptions {
    /// Write as `format` instead of following the extension.
    pub fn with_format(mut self, format: Option<Format>) -> Self {
        self.format = format;
        self
    }
    /// Replace existing output files (or not).
    pub fn with_force(mut self, force: bool) -> Self {
        self.force = force;
        self
    }
    /// Write 16-bit PNG codes with `mapping` (instead of the raster's own).
    pub fn with_png_mapping(mut self, mapping: Option<png::PngMapping>) -> Self {
        self.png_mapping = mapping;
        self
    }
    /// Let a format round values it cannot hold (see [`WriteOptions::round`]).
    pub fn with_round(mut self, round: bool) -> Self {
        self.round = round;
        self
    }
    /// Let a format drop georeferencing it cannot hold (see [`WriteOptions::drop_georef`]).
    pub fn with_drop_georef(mut self, drop: bool) -> Self {
        self.drop_georef = drop;
        self
    }
}

/// Open a raster file to be read band by band: raw `.f32` by seeking, GeoTIFF by chunks
/// (neither held whole, so they may be larger than memory and than `max_samples`); other
/// formats are read whole.
pub fn open_source(path: &Path, opts: &ReadOptions) -> Result<Box<dyn crate::model::RowSource>> {
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    let ctx = path.display().to_string();
    match format {
        Format::RawF32 => {
            let json_path = path.with_extension("json");
            let json = std::fs::read(&json_path)
                .map_err(|e| Error::io(format!("sidecar {}", json_path.display()), e))?;
            let s = raw::RawSource::open(path, &json).map_err(|e| e.context(&ctx))?;
            Ok(Box::new(s))
        }
        Format::GeoTiff => {
            // Bands are what is held; the whole may exceed the sample limit.
            let o = ReadOptions {
                max_samples: Some(u64::MAX),
                ..opts.clone()
            };
            Ok(Box::new(
                geotiff::Reader::open(path, &o).map_err(|e| e.context(&ctx))?,
            ))
        }
        Format::Vtz => Err(not_here()),
        _ => {
            let (raster, notes) = read_path_noted(path, opts)?;
            Ok(Box::new(Noted { raster, notes }))
        }
    }
}

/// A raster read whole, with what its reader noted.
struct Noted {
    raster: Raster,
    notes: Vec<String>,
}

impl crate::model::RowSource for Noted {
    fn width(&self) -> usize {
        self.raster.width
    }
    fn height(&self) -> usize {
        self.raster.height
    }
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        crate::model::RowSource::band(&mut self.raster, y0, rows)
    }
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }
}

/// Read a raster file, choosing the format by extension unless `opts.format` says.
pub(crate) fn read_path(path: &Path, opts: &ReadOptions) -> Result<Raster> {
    read_path_noted(path, opts).map(|(r, _)| r)
}

/// [`read_path`], with the notes of [`crate::model::RowSource::notes`].
fn read_path_noted(path: &Path, opts: &ReadOptions) -> Result<(Raster, Vec<String>)> {
    let mut notes = Vec::new();
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    let ctx = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| Error::io(&ctx, e))?;
    let r = match format {
        Format::GeoTiff => geotiff::read(&bytes, opts),
        Format::Png | Format::TerrainRgb | Format::Terrarium => {
            // The sidecar gives the mapping (unless the caller's overrides it) and the georef.
            let sidecar = png::read_sidecar(path)?;
            let mapping = match &opts.png_mapping {
                Some(m) => Some(m.clone()),
                None => sidecar.as_ref().map(|s| s.mapping.clone()),
            };
            let rgb = match format {
                Format::TerrainRgb => Some(png::RgbHeights::TerrainRgb),
                Format::Terrarium => Some(png::RgbHeights::Terrarium),
                _ => None,
            };
            png::read(&bytes, mapping.as_ref(), rgb, opts).map(|mut r| {
                r.georef = sidecar.and_then(|s| s.georef);
                if mapping.is_none() {
                    notes.extend(png::offset_note(&r));
                }
                r
            })
        }
        Format::Exr => exr::read(&bytes, opts),
        Format::Hgt => {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            hgt::read(&bytes, name, opts)
        }
        Format::Asc => asc::read(&bytes, opts).and_then(|mut r| {
            // The CRS, when a `.prj` lies beside the grid (GDAL's convention).
            if let (Some(g), Some((wkt, epsg))) = (r.georef.as_mut(), read_prj(path)?) {
                g.wkt = Some(wkt);
                g.epsg = epsg;
            }
            Ok(r)
        }),
        Format::RawF32 => {
            let json_path = path.with_extension("json");
            let json = std::fs::read(&json_path)
                .map_err(|e| Error::io(format!("sidecar {}", json_path.display()), e))?;
            raw::read(&bytes, &json, opts)
        }
        // The codec reads the container (`crate::read_path`); formats never call the codec.
        Format::Vtz => Err(not_here()),
    };
    let mut r = r.map_err(|e| e.context(&ctx))?;
    r.normalize_mask();
    r.validate().map_err(|e| e.context(&ctx))?;
    Ok((r, notes))
}

/// Encode a raster into the files `path` needs (the file itself plus any sidecar), without
/// touching the file system.
pub(crate) fn encode_path(
    raster: &Raster,
    path: &Path,
    opts: &WriteOptions,
) -> Result<Vec<OutputFile>> {
    raster.validate()?;
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    let one = |bytes: Vec<u8>| {
        vec![OutputFile {
            path: path.to_path_buf(),
            bytes,
        }]
    };
    Ok(match format {
        Format::GeoTiff => {
            let mut v = one(geotiff::write(raster)?);
            v.extend(geotiff_sidecar(path, raster.georef.as_ref()));
            v
        }
        Format::Png | Format::TerrainRgb | Format::Terrarium => {
            // A raster read from Terrain-RGB or Terrarium keeps that encoding in a .png unless
            // the caller asks for a 16-bit mapping.
            let rgb = match format {
                Format::TerrainRgb => Some(png::RgbHeights::TerrainRgb),
                Format::Terrarium => Some(png::RgbHeights::Terrarium),
                _ if opts.png_mapping.is_none() && raster.sample_type == SampleType::F32 => {
                    png::RgbHeights::of_mapping(&raster.mapping)
                }
                _ => None,
            };
            let georef = raster.georef.as_ref();
            let (png, sidecar, pam) = if let Some(k) = rgb {
                let (png, sidecar) = png::write_rgb_heights(raster, k, opts.round)?;
                // RGBA: GDAL sees four bands and takes voids from alpha; the PAM places it.
                let pam = pam::Pam {
                    georef,
                    ..Default::default()
                };
                (png, sidecar, pam)
            } else {
                let (png, sidecar, m) =
                    png::write_mapped(raster, opts.png_mapping.as_ref(), opts.round)?;
                let vm = ValueMapping {
                    scale: m.scale,
                    offset: m.offset,
                };
                // GDAL reads the codes: its nodata is the nodata code, the mapping its
                // offset and scale.
                let pam = pam::Pam {
                    georef,
                    nodata: m.nodata_code.map(f64::from),
                    offset_scale: (!vm.is_identity()).then_some((m.offset, m.scale)),
                    gdal_metadata: raster.gdal_metadata.as_deref(),
                };
                (png, sidecar, pam)
            };
            let mut v = one(png);
            if let Some(s) = sidecar {
                v.push(OutputFile {
                    path: png::sidecar_path(path),
                    bytes: s,
                });
            }
            if let Some(g) = georef {
                v.push(OutputFile {
                    path: pam::world_file_path(path),
                    bytes: pam::world_file(g),
                });
            }
            push_pam(&mut v, path, &pam);
            v
        }
        Format::Exr => {
            samples::check_f32(raster, opts.round, "OpenEXR's float32 samples")?;
            let mut v = one(exr::write(raster)?);
            // The EXR holds NaN wherever a sample is missing, whatever nodata was declared.
            let has_invalid = raster.valid_count() < raster.len();
            let pam = pam::Pam {
                georef: raster.georef.as_ref(),
                nodata: (has_invalid || raster.nodata.is_some()).then_some(f64::NAN),
                offset_scale: None,
                gdal_metadata: raster.gdal_metadata.as_deref(),
            };
            push_pam(&mut v, path, &pam);
            v
        }
        Format::Hgt => {
            // An .hgt is north-up by definition: a south-up raster is written flipped.
            let flipped = north_up(raster);
            let raster = &*flipped;
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            hgt::check_name(raster, name, opts.drop_georef)?;
            one(hgt::write(raster)?)
        }
        Format::Asc => {
            // An ESRI ASCII grid can only say north-up (`yllcorner` is the southern edge, the
            // first row the northern one): a south-up raster is written flipped, so GDAL
            // places every sample where the source has it.
            let flipped = north_up(raster);
            let raster = &*flipped;
            let mut v = one(asc::write(raster)?);
            // The header places the grid and declares its nodata; the CRS goes in the .prj,
            // GDAL_METADATA (when there is any) in the PAM.
            if let Some(prj) = raster.georef.as_ref().and_then(crs::prj_bytes) {
                v.push(OutputFile {
                    path: path.with_extension("prj"),
                    bytes: prj,
                });
            }
            let pam = pam::Pam {
                gdal_metadata: raster.gdal_metadata.as_deref(),
                ..Default::default()
            };
            push_pam(&mut v, path, &pam);
            v
        }
        Format::RawF32 => {
            samples::check_f32(raster, opts.round, "raw float32 samples")?;
            let (f32s, json) = raw::write(raster)?;
            vec![
                OutputFile {
                    path: path.to_path_buf(),
                    bytes: f32s,
                },
                OutputFile {
                    path: path.with_extension("json"),
                    bytes: json,
                },
                // For GDAL and QGIS, which do not read vtz's JSON.
                OutputFile {
                    path: path.with_extension("hdr"),
                    bytes: pam::envi_header(
                        raster.width,
                        raster.height,
                        raster.nodata.filter(|v| (*v as f32) as f64 == *v),
                        raster.georef.as_ref(),
                    ),
                },
            ]
        }
        Format::Vtz => return Err(not_here()),
    })
}

/// The PAM `.aux.xml` a GeoTIFF at `path` needs beside it: one for a CRS its GeoKeys cannot
/// carry (a WKT without an EPSG code or stored keys), which GDAL reads from there (it
/// prefers PAM to the file's own keys: GDAL_GEOREF_SOURCES starts with PAM); `None`
/// otherwise. The streaming writer's caller ([`GeoTiffWriter`]) writes it too.
pub fn geotiff_sidecar(path: &Path, georef: Option<&crate::model::Georef>) -> Option<OutputFile> {
    let g = georef.filter(|g| {
        g.wkt.is_some()
            && g.geokeys.is_none()
            && g.epsg.and_then(|e| u16::try_from(e).ok()).is_none()
    })?;
    let pam = pam::Pam {
        georef: Some(g),
        ..Default::default()
    };
    Some(OutputFile {
        path: pam::aux_path(path),
        bytes: pam::aux_xml(&pam)?,
    })
}

/// `r` with its rows in north-up order: a south-up raster (row 0 at the south, a negative
/// `Georef::pixel_size[1]`) flipped top to bottom with its georef moved to the northern edge,
/// for the formats that can only say north-up (ESRI ASCII grids, `.hgt`); any other raster
/// as it is. Every sample keeps its place on the ground.
pub(crate) fn north_up(r: &Raster) -> std::borrow::Cow<'_, Raster> {
    use crate::model::RasterType;
    let Some(g) = r.georef.as_ref().filter(|g| g.pixel_size[1] < 0.0) else {
        return std::borrow::Cow::Borrowed(r);
    };
    let w = r.width;
    let flip = |v: &[f64]| -> Vec<f64> { v.chunks_exact(w).rev().flatten().copied().collect() };
    let data = flip(&r.data);
    let mask = r
        .mask
        .as_ref()
        .map(|m| m.chunks_exact(w).rev().flatten().copied().collect());
    // The new row 0 is the old last row: its outer edge (area) or its centre (point).
    let mut north = g.window(
        0,
        match g.raster_type {
            RasterType::Area => r.height,
            RasterType::Point => r.height - 1,
        },
    );
    north.pixel_size[1] = -g.pixel_size[1];
    std::borrow::Cow::Owned(Raster {
        width: r.width,
        height: r.height,
        data,
        mask,
        georef: Some(north),
        ..r.clone_meta()
    })
}

/// Add the PAM `.aux.xml` of the file at `path` when it has anything to say.
fn push_pam(v: &mut Vec<OutputFile>, path: &Path, p: &pam::Pam) {
    if let Some(bytes) = pam::aux_xml(p) {
        v.push(OutputFile {
            path: pam::aux_path(path),
            bytes,
        });
    }
}

/// The CRS of the `.prj` beside `path` (`NAME.prj`, else `NAME.PRJ`): its text and EPSG code;
/// `None` when there is no such file.
fn read_prj(path: &Path) -> Result<Option<(String, Option<u32>)>> {
    for ext in ["prj", "PRJ"] {
        let p = path.with_extension(ext);
        match std::fs::read(&p) {
            Ok(b) => {
                let (text, epsg) = crs::parse_prj(&b);
                return Ok((!text.is_empty()).then_some((text, epsg)));
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(Error::io(format!("projection file {}", p.display()), e)),
        }
    }
    Ok(None)
}

/// Write a raster file (and its sidecar), atomically: see [`output::write_files`].
pub(crate) fn write_path(raster: &Raster, path: &Path, opts: &WriteOptions) -> Result<()> {
    let files = encode_path(raster, path, opts)?;
    output::write_files(&files, opts.force)
}

fn not_here() -> Error {
    Error::unsupported("a .vtz file is read and written by the codec, not as a raster format")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Georef, RasterType};

    /// A south-up 3 × 3 SRTM tile (row 0 at latitude -1): the `.hgt` and the ASCII grid,
    /// which can only say north-up, hold it flipped, each post where it lies.
    #[test]
    fn north_up_only_formats_get_a_south_up_raster_flipped() {
        let vals: Vec<f64> = (1..=9).map(f64::from).collect();
        let mut r = Raster::from_values(3, 3, vals, None, SampleType::I16).unwrap();
        r.georef = Some(Georef {
            origin: [10.0, -1.0],
            pixel_size: [0.5, -0.5],
            raster_type: RasterType::Point,
            epsg: Some(4326),
            wkt: None,
            geokeys: None,
        });
        let files = encode_path(&r, Path::new("S01E010.hgt"), &WriteOptions::default()).unwrap();
        let hgt = hgt::read(&files[0].bytes, "S01E010.hgt", &ReadOptions::default()).unwrap();
        assert_eq!(hgt.data, [7.0, 8.0, 9.0, 4.0, 5.0, 6.0, 1.0, 2.0, 3.0]);
        assert_eq!(hgt.georef.as_ref().unwrap().origin, [10.0, 0.0]);
        let files = encode_path(&r, Path::new("t.asc"), &WriteOptions::default()).unwrap();
        let asc = asc::read(&files[0].bytes, &ReadOptions::default()).unwrap();
        assert_eq!(asc.data, hgt.data);
        let g = asc.georef.unwrap();
        assert_eq!((g.origin, g.pixel_size), ([10.0, 0.0], [0.5, 0.5]));
        // A north-up raster is left as it is.
        let mut n = r.clone();
        n.georef.as_mut().unwrap().pixel_size[1] = 0.5;
        assert!(matches!(north_up(&n), std::borrow::Cow::Borrowed(_)));
    }
}
