//! Raster file formats: one file per format, each reading into a [`Raster`] and writing from
//! one; sidecars and atomic output beside them. Callers reach them through `vtz::read_path`
//! and `vtz::write_path` (the codec), which also read and write `.vtz`.
//!
//! Besides vtz's own sidecars, outputs get what GDAL reads where the format has no place for
//! georeferencing (module `pam`): `.asc` a `.prj` (module `crs`); PNG a world file and a PAM
//! `.aux.xml`; EXR a PAM `.aux.xml`; each also an `.aux.xml` for GDAL_METADATA.

pub(crate) mod asc;
mod crs;
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
pub use output::{OutputFile, PendingFile, remove_temporaries, write_file};
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

/// A GeoTIFF of `r` in memory, as `vtz decode -o X.tif` writes a raster (the same tags,
/// GeoTIFF keys included). The C ABI gives a 1 x 1 one to GDAL so that a CRS stored only as
/// GeoTIFF keys reads back exactly as from the source GeoTIFF.
pub fn geotiff_bytes(r: &Raster) -> Result<Vec<u8>> {
    geotiff::write(r)
}

/// Raster file formats vtz reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// GeoTIFF (`.tif`, `.tiff`).
    GeoTiff,
    /// 16-bit greyscale PNG with a value mapping; Mapbox Terrain-RGB PNGs are read too.
    Png,
    /// Mapbox Terrain-RGB PNG (height = -10000 + (R·65536 + G·256 + B)·0.1).
    TerrainRgb,
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
                "cannot tell the format of {} from its extension '{ext}' (use --format; known: tif, png, terrain-rgb, exr, hgt, asc, f32, vtz)",
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
            "exr" => Format::Exr,
            "hgt" => Format::Hgt,
            "asc" | "ascii" => Format::Asc,
            "f32" | "raw" => Format::RawF32,
            "vtz" => Format::Vtz,
            other => return Err(Error::invalid(format!("unknown raster format '{other}'"))),
        })
    }

    /// The format's name for people.
    pub fn name(self) -> &'static str {
        match self {
            Format::GeoTiff => "GeoTIFF",
            Format::Png => "PNG16",
            Format::TerrainRgb => "Terrain-RGB PNG",
            Format::Exr => "OpenEXR",
            Format::Hgt => "SRTM hgt",
            Format::Asc => "ESRI ASCII grid",
            Format::RawF32 => "raw f32 + json",
            Format::Vtz => "vtz",
        }
    }
}

/// Options for reading rasters.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Force a format instead of guessing from the extension.
    pub format: Option<Format>,
    /// Value mapping for 16-bit PNG input (overrides a sidecar).
    pub png_mapping: Option<png::PngMapping>,
    /// Upper bound on samples a reader may allocate (defaults to 2^28, as [`crate::Limits`]).
    pub max_samples: Option<u64>,
}

impl ReadOptions {
    /// The sample limit in force.
    pub fn max_samples(&self) -> u64 {
        self.max_samples.unwrap_or(DEFAULT_MAX_SAMPLES)
    }
}

/// Options for writing rasters.
#[derive(Clone, Debug, Default)]
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
                geotiff::StreamReader::open(path, &o).map_err(|e| e.context(&ctx))?,
            ))
        }
        Format::Vtz => Err(not_here()),
        _ => Ok(Box::new(read_path(path, opts)?)),
    }
}

/// Read a raster file, choosing the format by extension unless `opts.format` says.
pub(crate) fn read_path(path: &Path, opts: &ReadOptions) -> Result<Raster> {
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    let ctx = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| Error::io(&ctx, e))?;
    let r = match format {
        Format::GeoTiff => geotiff::read(&bytes, opts),
        Format::Png | Format::TerrainRgb => {
            // The sidecar gives the mapping (unless the caller's overrides it) and the georef.
            let sidecar = png::read_sidecar(path)?;
            let mapping = match &opts.png_mapping {
                Some(m) => Some(m.clone()),
                None => sidecar.as_ref().map(|s| s.mapping.clone()),
            };
            png::read(&bytes, mapping.as_ref(), format == Format::TerrainRgb, opts).map(|mut r| {
                r.georef = sidecar.and_then(|s| s.georef);
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
    Ok(r)
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
        Format::Png | Format::TerrainRgb => {
            // A raster read from Terrain-RGB keeps that encoding in a .png unless the caller
            // asks for a 16-bit mapping.
            let terrain_rgb = format == Format::TerrainRgb
                || (opts.png_mapping.is_none()
                    && raster.mapping == png::TERRAIN_RGB
                    && raster.sample_type == SampleType::F32);
            let georef = raster.georef.as_ref();
            let (png, sidecar, pam) = if terrain_rgb {
                let (png, sidecar) = png::write_terrain_rgb(raster, opts.round)?;
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
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            hgt::check_name(raster, name, opts.drop_georef)?;
            one(hgt::write(raster)?)
        }
        Format::Asc => {
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
