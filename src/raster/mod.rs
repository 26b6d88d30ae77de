//! The raster model (samples, validity mask, sample type, georeferencing) and format dispatch.
//!
//! One file per raster format lives beside this one; only this module and those files know
//! file formats. Every format reads into the same [`Raster`] and writes from it.

pub mod asc;
pub mod exr;
pub mod geotiff;
pub mod hgt;
pub mod png;
pub mod raw;

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The type the source stored its samples in. Values are held as `f64` in memory (exact for
/// every type listed), and writers convert back to this type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SampleType {
    U8,
    I16,
    U16,
    I32,
    F32,
    F64,
}

impl SampleType {
    /// Stable on-disk code (see spec/FORMAT.md).
    pub fn code(self) -> u8 {
        match self {
            SampleType::U8 => 0,
            SampleType::I16 => 1,
            SampleType::U16 => 2,
            SampleType::I32 => 3,
            SampleType::F32 => 4,
            SampleType::F64 => 5,
        }
    }
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            0 => SampleType::U8,
            1 => SampleType::I16,
            2 => SampleType::U16,
            3 => SampleType::I32,
            4 => SampleType::F32,
            5 => SampleType::F64,
            _ => return None,
        })
    }
    pub fn name(self) -> &'static str {
        match self {
            SampleType::U8 => "u8",
            SampleType::I16 => "i16",
            SampleType::U16 => "u16",
            SampleType::I32 => "i32",
            SampleType::F32 => "f32",
            SampleType::F64 => "f64",
        }
    }
    /// Bits one sample takes in the source type (for compression ratios).
    pub fn bits(self) -> u32 {
        match self {
            SampleType::U8 => 8,
            SampleType::I16 | SampleType::U16 => 16,
            SampleType::I32 | SampleType::F32 => 32,
            SampleType::F64 => 64,
        }
    }
    pub fn is_integer(self) -> bool {
        matches!(
            self,
            SampleType::U8 | SampleType::I16 | SampleType::U16 | SampleType::I32
        )
    }
    /// Inclusive range of integer codes this type can hold (None for floats).
    pub fn int_range(self) -> Option<(f64, f64)> {
        match self {
            SampleType::U8 => Some((0.0, 255.0)),
            SampleType::I16 => Some((i16::MIN as f64, i16::MAX as f64)),
            SampleType::U16 => Some((0.0, u16::MAX as f64)),
            SampleType::I32 => Some((i32::MIN as f64, i32::MAX as f64)),
            _ => None,
        }
    }
}

/// Whether a pixel value describes the whole cell (GeoTIFF `PixelIsArea`) or the point at
/// its centre (`PixelIsPoint`, e.g. SRTM `.hgt` posts).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RasterType {
    Area,
    Point,
}

/// The GeoTIFF georeferencing tags, kept verbatim so that a GeoTIFF → vtz → GeoTIFF round
/// trip gives GDAL exactly the same CRS (GDAL needs all three GeoKey tags).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct GeoKeys {
    /// GeoKeyDirectoryTag (34735), all shorts including the 4-short header.
    pub directory: Vec<u16>,
    /// GeoDoubleParamsTag (34736).
    pub doubles: Vec<f64>,
    /// GeoAsciiParamsTag (34737), including its `|` separators (no trailing NUL).
    pub ascii: String,
}

/// Where the raster sits on the Earth (or in a model space).
#[derive(Clone, Debug, PartialEq)]
pub struct Georef {
    /// Model coordinates (x = east, y = north) of the upper-left *corner* of pixel (0, 0)
    /// for [`RasterType::Area`], of its *centre* for [`RasterType::Point`].
    pub origin: [f64; 2],
    /// Pixel size along x (to the east) and y (to the south), positive for north-up rasters.
    pub pixel_size: [f64; 2],
    pub raster_type: RasterType,
    /// EPSG code of the CRS when known.
    pub epsg: Option<u32>,
    /// A WKT or PROJ description of the CRS when the source gave one.
    pub wkt: Option<String>,
    /// Raw GeoTIFF keys when the source was a GeoTIFF (or a .vtz made from one).
    pub geokeys: Option<GeoKeys>,
}

impl Georef {
    /// Georef of a rectangular sub-window starting at pixel (x0, y0), or of a grid resampled
    /// by `scale` (output pixel = input pixel / scale).
    pub fn window(&self, x0: usize, y0: usize) -> Georef {
        let mut g = self.clone();
        g.origin[0] += x0 as f64 * self.pixel_size[0];
        g.origin[1] -= y0 as f64 * self.pixel_size[1];
        g
    }
}

/// How integer codes map to physical values: `value = offset + scale * code`
/// (e.g. a 16-bit PNG holding `metres + 32768`, or decimetres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValueMapping {
    pub scale: f64,
    pub offset: f64,
}

impl Default for ValueMapping {
    fn default() -> Self {
        ValueMapping {
            scale: 1.0,
            offset: 0.0,
        }
    }
}

impl ValueMapping {
    pub fn is_identity(&self) -> bool {
        self.scale == 1.0 && self.offset == 0.0
    }
    pub fn to_value(&self, code: f64) -> f64 {
        self.offset + self.scale * code
    }
    pub fn to_code(&self, value: f64) -> f64 {
        (value - self.offset) / self.scale
    }
}

/// A gridded elevation raster: `width × height` samples, row-major, row 0 = north.
///
/// Invariants (checked by [`Raster::validate`]): `data.len() == width * height`; when
/// `mask` is `Some`, it has the same length and `false` marks nodata; every invalid sample
/// holds `nodata` (or NaN when no nodata value is declared); every valid sample is finite.
#[derive(Clone, Debug, PartialEq)]
pub struct Raster {
    pub width: usize,
    pub height: usize,
    /// Physical values (after the value mapping), row-major.
    pub data: Vec<f64>,
    /// Validity mask: `None` = every sample valid; `Some(m)`: `m[i] == false` is nodata.
    pub mask: Option<Vec<bool>>,
    /// The nodata value the source declared (kept even when no sample uses it).
    pub nodata: Option<f64>,
    pub sample_type: SampleType,
    /// Mapping between stored integer codes and physical values.
    pub mapping: ValueMapping,
    pub georef: Option<Georef>,
}

impl Raster {
    /// A raster from physical values. Samples equal to `nodata`, and NaN samples, become
    /// invalid (NaN input is treated as nodata); infinite samples are rejected.
    pub fn from_values(
        width: usize,
        height: usize,
        mut data: Vec<f64>,
        nodata: Option<f64>,
        sample_type: SampleType,
    ) -> Result<Raster> {
        if width == 0 || height == 0 {
            return Err(Error::invalid(format!(
                "raster size {width}x{height} is empty"
            )));
        }
        let n = width
            .checked_mul(height)
            .ok_or_else(|| Error::limit("raster size overflows"))?;
        if data.len() != n {
            return Err(Error::invalid(format!(
                "raster {width}x{height} needs {n} samples, got {}",
                data.len()
            )));
        }
        let fill = nodata.unwrap_or(f64::NAN);
        let mut mask: Option<Vec<bool>> = None;
        for (i, d) in data.iter_mut().enumerate() {
            let v = *d;
            let invalid = v.is_nan() || nodata.is_some_and(|nd| v == nd);
            if v.is_infinite() && !nodata.is_some_and(|nd| v == nd) {
                return Err(Error::invalid(format!(
                    "sample {i} (row {}, col {}) is infinite",
                    i / width,
                    i % width
                )));
            }
            if invalid {
                mask.get_or_insert_with(|| vec![true; n])[i] = false;
                *d = fill;
            }
        }
        Ok(Raster {
            width,
            height,
            data,
            mask,
            nodata,
            sample_type,
            mapping: ValueMapping::default(),
            georef: None,
        })
    }

    pub fn len(&self) -> usize {
        self.width * self.height
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    pub fn is_valid(&self, i: usize) -> bool {
        self.mask.as_ref().is_none_or(|m| m[i])
    }

    /// Number of valid samples.
    pub fn valid_count(&self) -> usize {
        match &self.mask {
            None => self.len(),
            Some(m) => m.iter().filter(|&&b| b).count(),
        }
    }

    /// (min, max) over valid samples, `None` when there is none.
    pub fn valid_range(&self) -> Option<(f64, f64)> {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for (i, &v) in self.data.iter().enumerate() {
            if self.is_valid(i) {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        (lo <= hi).then_some((lo, hi))
    }

    /// The value written into invalid samples: the declared nodata, else NaN.
    pub fn fill_value(&self) -> f64 {
        self.nodata.unwrap_or(f64::NAN)
    }

    /// The samples with every invalid one replaced by a nearby valid value (the previous
    /// valid sample of its row, else the next; rows without any copy the nearest filled
    /// row; all zeros when nothing is valid): a stand-in for transforms that need every
    /// sample (FIS).
    pub fn filled(&self) -> Vec<f64> {
        let mut out = self.data.clone();
        if let Some(mask) = &self.mask {
            if !fill_invalid(&mut out, mask, self.width, self.height, |a, _, _, _| a) {
                out.iter_mut().for_each(|v| *v = 0.0);
            }
        }
        out
    }

    /// Check the invariants listed on the type.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(Error::invalid("raster is empty"));
        }
        if self.data.len() != self.width * self.height {
            return Err(Error::invalid("raster data length does not match its size"));
        }
        if let Some(m) = &self.mask {
            if m.len() != self.data.len() {
                return Err(Error::invalid("mask length does not match raster size"));
            }
        }
        for (i, &v) in self.data.iter().enumerate() {
            if self.is_valid(i) && !v.is_finite() {
                return Err(Error::invalid(format!("valid sample {i} is not finite")));
            }
        }
        if let Some(nd) = self.nodata {
            if nd.is_nan() {
                return Err(Error::invalid("nodata value is NaN"));
            }
        }
        Ok(())
    }

    /// Drop an all-true mask (so "no nodata" has one representation).
    pub fn normalize_mask(&mut self) {
        if self.mask.as_ref().is_some_and(|m| m.iter().all(|&b| b)) {
            self.mask = None;
        }
    }
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
    /// Upper bound on samples a reader may allocate (defaults to [`DEFAULT_MAX_SAMPLES`]).
    pub max_samples: Option<u64>,
}

/// Default upper bound on the number of samples of a raster read from a file.
pub const DEFAULT_MAX_SAMPLES: u64 = 1 << 28;

impl ReadOptions {
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
}

/// One output file a writer produced (a format may need a sidecar).
#[derive(Clone, Debug)]
pub struct OutputFile {
    pub path: PathBuf,
    pub bytes: Vec<u8>,
}

/// Fill the invalid samples (per `mask`) of a `w`-wide row-major grid in place: a gap
/// between two valid samples `a` and `b` of a row gets `between(v[a], v[b], i − a, b − a)`
/// at each index i, a gap at a row's start or end the nearest valid value of the row, and a
/// row without valid samples a copy of the nearest row that has one. Returns false (and
/// changes nothing) when no sample is valid. Encoders only: decoders write the nodata fill.
pub(crate) fn fill_invalid<T: Copy>(
    v: &mut [T],
    mask: &[bool],
    w: usize,
    h: usize,
    between: impl Fn(T, T, usize, usize) -> T,
) -> bool {
    let mut has_valid = vec![false; h];
    for y in 0..h {
        let row = &mut v[y * w..][..w];
        let m = &mask[y * w..][..w];
        let mut prev: Option<usize> = None;
        let mut x = 0;
        while x < w {
            if m[x] {
                prev = Some(x);
                x += 1;
                continue;
            }
            let start = x;
            while x < w && !m[x] {
                x += 1;
            }
            match (prev, (x < w).then_some(x)) {
                (Some(a), Some(b)) => {
                    let (va, vb) = (row[a], row[b]);
                    for (i, c) in row.iter_mut().enumerate().take(b).skip(start) {
                        *c = between(va, vb, i - a, b - a);
                    }
                }
                (Some(a), None) => {
                    let va = row[a];
                    row[start..x].iter_mut().for_each(|c| *c = va);
                }
                (None, Some(b)) => {
                    let vb = row[b];
                    row[start..b].iter_mut().for_each(|c| *c = vb);
                }
                (None, None) => {}
            }
        }
        has_valid[y] = prev.is_some();
    }
    let Some(first) = has_valid.iter().position(|&b| b) else {
        return false;
    };
    let mut last = first;
    for (y, &valid) in has_valid.iter().enumerate() {
        if valid {
            last = y;
        } else {
            let src = if y < first { first } else { last };
            v.copy_within(src * w..src * w + w, y * w);
        }
    }
    true
}

/// Check that `width × height` samples are within `max` before allocating them.
pub fn check_size(width: u64, height: u64, max: u64) -> Result<usize> {
    if width == 0 || height == 0 {
        return Err(Error::corrupt(format!(
            "raster size {width}x{height} is empty"
        )));
    }
    let n = width
        .checked_mul(height)
        .ok_or_else(|| Error::limit(format!("raster size {width}x{height} overflows")))?;
    if n > max {
        return Err(Error::limit(format!(
            "raster of {width}x{height} = {n} samples is over the limit of {max}"
        )));
    }
    usize::try_from(n).map_err(|_| Error::limit("raster too large for this platform"))
}

/// Read a raster file, choosing the format by extension unless `opts.format` says.
pub fn read_path(path: &Path, opts: &ReadOptions) -> Result<Raster> {
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
        Format::Asc => asc::read(&bytes, opts),
        Format::RawF32 => {
            let json_path = path.with_extension("json");
            let json = std::fs::read(&json_path)
                .map_err(|e| Error::io(format!("sidecar {}", json_path.display()), e))?;
            raw::read(&bytes, &json, opts)
        }
        Format::Vtz => crate::decode_with(&bytes, &crate::DecodeOptions::default()),
    };
    let mut r = r.map_err(|e| e.context(&ctx))?;
    r.normalize_mask();
    r.validate().map_err(|e| e.context(&ctx))?;
    Ok(r)
}

/// Encode a raster into the files `path` needs (the file itself plus any sidecar), without
/// touching the file system.
pub fn encode_path(raster: &Raster, path: &Path, opts: &WriteOptions) -> Result<Vec<OutputFile>> {
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
        Format::GeoTiff => one(geotiff::write(raster)?),
        Format::Png | Format::TerrainRgb => {
            // A raster read from Terrain-RGB keeps that encoding in a .png unless the caller
            // asks for a 16-bit mapping.
            let terrain_rgb = format == Format::TerrainRgb
                || (opts.png_mapping.is_none()
                    && raster.mapping == png::TERRAIN_RGB
                    && raster.sample_type == SampleType::F32);
            let (png, sidecar) = if terrain_rgb {
                png::write_terrain_rgb(raster)?
            } else {
                png::write(raster, opts.png_mapping.as_ref())?
            };
            let mut v = one(png);
            if let Some(s) = sidecar {
                v.push(OutputFile {
                    path: png::sidecar_path(path),
                    bytes: s,
                });
            }
            v
        }
        Format::Exr => one(exr::write(raster)?),
        Format::Hgt => one(hgt::write(raster)?),
        Format::Asc => one(asc::write(raster)?),
        Format::RawF32 => {
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
            ]
        }
        Format::Vtz => one(crate::encode(raster, &crate::EncodeOptions::default())?),
    })
}

/// Write a raster file (and its sidecar), atomically: see [`crate::fsio::write_files`].
pub fn write_path(raster: &Raster, path: &Path, opts: &WriteOptions) -> Result<()> {
    let files = encode_path(raster, path, opts)?;
    crate::fsio::write_files(&files, opts.force)
}
