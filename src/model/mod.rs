//! The raster model: samples, validity mask, sample type, value mapping and georeferencing.
//!
//! Every format reads into a [`Raster`] and writes from one; every method encodes one.

use crate::error::{Error, Result};
use std::str::FromStr;

mod fill;
pub(crate) mod flat;
mod points;
pub(crate) use fill::fill_invalid;
pub use points::PointSet;

/// The type the source stored its samples in. Values are held as `f64` in memory (exact for
/// every type listed), and writers convert back to this type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SampleType {
    /// Unsigned 8-bit integers.
    U8,
    /// Signed 16-bit integers (SRTM, most DEM GeoTIFFs).
    I16,
    /// Unsigned 16-bit integers (16-bit PNG height maps).
    U16,
    /// Signed 32-bit integers.
    I32,
    /// 32-bit floats.
    F32,
    /// 64-bit floats.
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
    /// The type of an on-disk code, if it is one.
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
    /// The type's short name (`i16`, `f32`, …).
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
    /// Whether the type holds integers.
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
    /// The value of this type nearest `v` under the value mapping `m`, as every decoder
    /// produces its samples: f32 rounding; for integer types the nearest code
    /// `round((v − offset) / scale)` clamped to the type's range, mapped back as
    /// `offset + scale · code`; f64 unchanged.
    #[inline]
    pub fn nearest_value(self, v: f64, m: ValueMapping) -> f64 {
        match self {
            SampleType::F32 => v as f32 as f64,
            SampleType::F64 => v,
            st => {
                let (lo, hi) = st.int_range().expect("integer type");
                let code = ((v - m.offset) / m.scale).round().clamp(lo, hi);
                m.offset + m.scale * code
            }
        }
    }
    /// Whether `v` is a value of this type under the value mapping `m`: finite and what
    /// [`SampleType::nearest_value`] leaves unchanged (integer types: `offset + scale · code`
    /// for an integer code in the type's range, computed as a decoder computes it; f32:
    /// exactly an f32; f64: any finite number). A value a file stores as a sample's value
    /// (a flat region's, a range's ends) must be one, or the file is corrupt.
    pub fn holds(self, v: f64, m: ValueMapping) -> bool {
        v.is_finite() && self.nearest_value(v, m) == v
    }
    /// `Ok` when `v` is a value of this type under `m` ([`SampleType::holds`]), else the
    /// reason, naming `what` and the value: "<what> 2.1e-314 is not a value of i16".
    pub(crate) fn check_holds(
        self,
        what: &str,
        v: f64,
        m: ValueMapping,
    ) -> std::result::Result<(), String> {
        if self.holds(v, m) {
            return Ok(());
        }
        let of = if self.is_integer() && !m.is_identity() {
            format!(
                "{} codes mapped by value = {:?} + {:?}·code",
                self.name(),
                m.offset,
                m.scale
            )
        } else {
            self.name().to_string()
        };
        Err(format!("{what} {v:?} is not a value of {of}"))
    }
}

/// Whether a pixel value describes the whole cell (GeoTIFF `PixelIsArea`) or the point at
/// its centre (`PixelIsPoint`, e.g. SRTM `.hgt` posts).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RasterType {
    /// A value describes the whole cell (GeoTIFF `PixelIsArea`).
    Area,
    /// A value describes the point at the cell's centre (`PixelIsPoint`).
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
    /// Pixel size along x (to the east) and y (to the south), positive for north-up rasters;
    /// y is negative for a south-up raster (row 0 at the south, as NetCDF/GRIB conversions
    /// give): GeoTIFF writes it as a ModelTransformation, ASCII grids and `.hgt` flipped.
    pub pixel_size: [f64; 2],
    /// Whether a pixel is an area or the point at its centre.
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

    /// GDAL's geotransform: `[x0, dx, 0, y0, 0, -dy]`, (x0, y0) the upper-left *corner* of
    /// pixel (0, 0) in model coordinates (a [`RasterType::Point`] origin moved by half a
    /// pixel), dx and dy the [`Georef::pixel_size`]; a model position is
    /// `(x0 + col·dx, y0 − row·dy)` for a fractional pixel position (col, row).
    pub fn geotransform(&self) -> [f64; 6] {
        let [dx, dy] = self.pixel_size;
        let [x, y] = match self.raster_type {
            RasterType::Area => self.origin,
            RasterType::Point => [self.origin[0] - 0.5 * dx, self.origin[1] + 0.5 * dy],
        };
        [x, dx, 0.0, y, 0.0, -dy]
    }

    /// Model coordinates (x east, y north) of the centre of the sample at column `col`, row
    /// `row` (fractional positions between centres too): `origin + (col + c)·dx`,
    /// `origin − (row + c)·dy`, c = ½ for [`RasterType::Area`] (its origin is a corner), 0 for
    /// [`RasterType::Point`].
    pub fn sample_centre(&self, col: f64, row: f64) -> [f64; 2] {
        let c = match self.raster_type {
            RasterType::Area => 0.5,
            RasterType::Point => 0.0,
        };
        [
            self.origin[0] + (col + c) * self.pixel_size[0],
            self.origin[1] - (row + c) * self.pixel_size[1],
        ]
    }
}

/// How integer codes map to physical values: `value = offset + scale * code`
/// (e.g. a 16-bit PNG holding `metres + 32768`, or decimetres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValueMapping {
    /// Value per code step.
    pub scale: f64,
    /// Value of code 0.
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
    /// Whether codes are the values themselves.
    pub fn is_identity(&self) -> bool {
        self.scale == 1.0 && self.offset == 0.0
    }
    /// The value of a code.
    pub fn to_value(&self, code: f64) -> f64 {
        self.offset + self.scale * code
    }
    /// The (fractional) code of a value.
    pub fn to_code(&self, value: f64) -> f64 {
        (value - self.offset) / self.scale
    }
}

/// How a reader that gives each band one data type (GDAL, a GeoTIFF, QGIS, rasterio)
/// sees the samples of a sample type under a value mapping. One rule, used by `vtz decode`'s
/// and `vtz convert`'s GeoTIFFs, `vtz info`, the C ABI (`VtzInfo::value_type`) and the GDAL
/// plugin:
///
/// - the identity mapping, or a float sample type: the values, in the sample type;
/// - integer codes with scale ±1 and a whole offset: the values, in the smallest of u8, i16,
///   u16, i32 that holds `offset + scale · c` for every code `c` of the sample type (and the
///   nodata value): a u16 PNG mapped by −32768 is i16 (GDAL's Int16);
/// - any other mapping (a scale other than ±1, a fractional offset, or values no such type
///   holds): the codes, in the sample type, with the mapping as GDAL's band offset and scale
///   (`GetOffset`/`GetScale`, a GeoTIFF's GDAL_METADATA `OFFSET`/`SCALE` items), so GDAL
///   readers see the values;
/// - when even the nodata value is not a code of the sample type: the values as f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OutputType {
    /// The values themselves, in this type.
    Values(SampleType),
    /// The integer codes, in this (the file's) sample type, with this mapping as the band's
    /// offset and scale (`value = offset + scale · code`).
    Codes(SampleType, ValueMapping),
}

impl OutputType {
    /// The output type of samples of `sample_type` under `mapping`, with the declared nodata
    /// value `nodata` (a value, not a code).
    pub fn of(sample_type: SampleType, mapping: ValueMapping, nodata: Option<f64>) -> OutputType {
        let Some((lo, hi)) = sample_type.int_range() else {
            return OutputType::Values(sample_type);
        };
        if mapping.is_identity() {
            return OutputType::Values(sample_type);
        }
        if mapping.scale.abs() == 1.0 && mapping.offset.fract() == 0.0 {
            let (a, b) = (mapping.to_value(lo), mapping.to_value(hi));
            let (vlo, vhi) = (a.min(b), a.max(b));
            let holds = |t: SampleType| {
                let (tlo, thi) = t.int_range().expect("an integer type");
                vlo >= tlo
                    && vhi <= thi
                    && nodata.is_none_or(|nd| nd.fract() == 0.0 && nd >= tlo && nd <= thi)
            };
            let types = [
                SampleType::U8,
                SampleType::I16,
                SampleType::U16,
                SampleType::I32,
            ];
            if let Some(t) = types.into_iter().find(|&t| holds(t)) {
                return OutputType::Values(t);
            }
        }
        let nodata_is_code = nodata.is_none_or(|nd| {
            let c = mapping.to_code(nd).round();
            c >= lo && c <= hi && mapping.to_value(c) == nd
        });
        if nodata_is_code {
            OutputType::Codes(sample_type, mapping)
        } else {
            OutputType::Values(SampleType::F64)
        }
    }

    /// The type a reader stores (the values' type, or the codes' type).
    pub fn sample_type(self) -> SampleType {
        match self {
            OutputType::Values(t) | OutputType::Codes(t, _) => t,
        }
    }

    /// The band offset and scale a reader applies (`None`: the samples are the values).
    pub fn offset_scale(self) -> Option<ValueMapping> {
        match self {
            OutputType::Values(_) => None,
            OutputType::Codes(_, m) => Some(m),
        }
    }

    /// A value as the reader stores it: itself, or its code (`(v − offset) / scale`,
    /// rounded to the nearest code; NaN stays NaN).
    pub fn stored(self, v: f64) -> f64 {
        match self {
            OutputType::Values(_) => v,
            OutputType::Codes(_, m) => m.to_code(v).round(),
        }
    }

    /// How `vtz info` names it: `i16`, or `u16 codes, GDAL offset -10 scale 0.1`.
    pub fn describe(self) -> String {
        match self {
            OutputType::Values(t) => t.name().to_string(),
            OutputType::Codes(t, m) => format!(
                "{} codes with GDAL offset {} and scale {}",
                t.name(),
                m.offset,
                m.scale
            ),
        }
    }
}

/// A gridded elevation raster: `width × height` samples, row-major, row 0 = north.
///
/// Invariants (checked by [`Raster::validate`]): `data.len() == width * height`; when
/// `mask` is `Some`, it has the same length and `false` marks nodata; every invalid sample
/// holds `nodata` (or NaN when no nodata value is declared); every valid sample is finite.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Raster {
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Physical values (after the value mapping), row-major.
    pub data: Vec<f64>,
    /// Validity mask: `None` = every sample valid; `Some(m)`: `m[i] == false` is nodata.
    pub mask: Option<Vec<bool>>,
    /// The nodata value the source declared (kept even when no sample uses it).
    pub nodata: Option<f64>,
    /// The type the source stored samples in (decoders give this type back).
    pub sample_type: SampleType,
    /// Mapping between stored integer codes and physical values.
    pub mapping: ValueMapping,
    /// Where the raster sits, when the source said.
    pub georef: Option<Georef>,
    /// GDAL's own metadata as the source stored it: the XML of GeoTIFF tag 42112
    /// (`GDAL_METADATA`, `<GDALMetadata><Item name=".." sample=".." role="..">..</Item>…`),
    /// verbatim. It holds what GDAL knows beyond the samples (band description, units, scale
    /// and offset, free items), so it is kept through `.vtz` and written back to GeoTIFF, and
    /// translated into the `.aux.xml` of formats without such a tag. vtz never interprets it
    /// when encoding; samples are not rescaled by its scale/offset. A windowed or resampled
    /// decode drops its `STATISTICS_*` items, which describe the whole source.
    pub gdal_metadata: Option<String>,
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
        let raster = Raster::from_parts(width, height, data, mask, nodata, sample_type);
        Ok(raster)
    }

    /// A raster of samples a reader has decoded and masked itself (no checks, unlike
    /// [`Raster::from_values`]), with the identity mapping and no georef.
    pub(crate) fn from_parts(
        width: usize,
        height: usize,
        data: Vec<f64>,
        mask: Option<Vec<bool>>,
        nodata: Option<f64>,
        sample_type: SampleType,
    ) -> Raster {
        Raster {
            width,
            height,
            data,
            mask,
            nodata,
            sample_type,
            mapping: ValueMapping::default(),
            georef: None,
            gdal_metadata: None,
        }
    }

    /// Samples (width × height).
    pub fn len(&self) -> usize {
        self.width * self.height
    }
    /// Whether the raster has no samples (never, for a valid raster).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    /// Whether sample `i` holds data (not nodata).
    pub fn is_valid(&self, i: usize) -> bool {
        self.mask.as_ref().is_none_or(|m| m[i])
    }

    /// The samples of window `w` (inside the raster) as a raster of their own: same type,
    /// mapping and nodata, no georef.
    pub(crate) fn crop(&self, w: Window) -> Raster {
        let rows = w.y..w.y + w.height;
        let pick = |i: usize| (i % w.width + w.x) + (i / w.width + w.y) * self.width;
        debug_assert!(w.x + w.width <= self.width && rows.end <= self.height);
        let data = (0..w.width * w.height)
            .map(|i| self.data[pick(i)])
            .collect();
        let mask = self
            .mask
            .as_ref()
            .map(|m| (0..w.width * w.height).map(|i| m[pick(i)]).collect());
        Raster {
            mapping: self.mapping,
            ..Raster::from_parts(w.width, w.height, data, mask, self.nodata, self.sample_type)
        }
    }

    /// The spacing of the values the source can hold, when it has one: the mapping's step
    /// for integer sample types, 1 for float data whose valid samples are all whole numbers.
    /// A bound below half of it can only be met by the exact values.
    pub(crate) fn value_step(&self) -> Option<f64> {
        if self.sample_type.is_integer() {
            return Some(self.mapping.scale.abs());
        }
        let whole = (0..self.len()).all(|i| !self.is_valid(i) || self.data[i].fract() == 0.0);
        whole.then_some(1.0)
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

    /// A copy whose mask also marks the samples of the flat regions `flat` (values, NaN
    /// outside them) invalid: what the methods encode when the regions have a section.
    pub(crate) fn without_flat(&self, flat: &[f64]) -> Raster {
        let mask = (0..self.len())
            .map(|i| self.is_valid(i) && flat[i].is_nan())
            .collect();
        Raster {
            mask: Some(mask),
            gdal_metadata: None,
            ..self.clone()
        }
    }

    /// Drop an all-true mask (so "no nodata" has one representation).
    pub fn normalize_mask(&mut self) {
        if self.mask.as_ref().is_some_and(|m| m.iter().all(|&b| b)) {
            self.mask = None;
        }
    }
}

/// Default upper bound on the number of samples of a raster read from a file.
pub const DEFAULT_MAX_SAMPLES: u64 = 1 << 28;

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

/// A rectangle of samples: column, row, width, height.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// First column.
    pub x: usize,
    /// First row.
    pub y: usize,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl Window {
    /// Parse `x,y,w,h`.
    pub fn parse(s: &str) -> Result<Window> {
        let v: Vec<usize> = s
            .split(',')
            .map(|p| p.trim().parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| Error::invalid(format!("window '{s}' is not x,y,width,height")))?;
        match v[..] {
            [x, y, width, height] => Ok(Window {
                x,
                y,
                width,
                height,
            }),
            _ => Err(Error::invalid(format!(
                "window '{s}' is not x,y,width,height"
            ))),
        }
    }

    /// The whole of a `w × h` raster.
    pub fn full(w: usize, h: usize) -> Window {
        Window {
            x: 0,
            y: 0,
            width: w,
            height: h,
        }
    }
}

impl FromStr for Window {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Window::parse(s)
    }
}

/// A raster read a band of full-width rows at a time, so that a file larger than memory can
/// be encoded tile row by tile row (raw `.f32` by seeking, GeoTIFF by chunks).
pub trait RowSource: Send {
    /// Samples per row.
    fn width(&self) -> usize;
    /// Rows.
    fn height(&self) -> usize;
    /// Rows `y0..y0 + rows`, full width, with the source's sample type, mapping, nodata and
    /// GDAL metadata, and its georef moved to the band's first row.
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster>;
    /// What the reader wants the user told about how it read the file (one line each,
    /// without a "note:" prefix): a GeoTIFF's mask band taken as nodata, 16-bit PNG codes
    /// that look like heights + 32768. None by default.
    fn notes(&self) -> Vec<String> {
        Vec::new()
    }
}

/// A raster already in memory as a [`RowSource`].
pub struct InMemory<'a>(pub &'a Raster);

impl RowSource for InMemory<'_> {
    fn width(&self) -> usize {
        self.0.width
    }
    fn height(&self) -> usize {
        self.0.height
    }
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        let r = self.0;
        if y0 + rows > r.height {
            return Err(crate::error::Error::invalid("band outside the raster"));
        }
        let (a, b) = (y0 * r.width, (y0 + rows) * r.width);
        Ok(Raster {
            width: r.width,
            height: rows,
            data: r.data[a..b].to_vec(),
            mask: r.mask.as_ref().map(|m| m[a..b].to_vec()),
            georef: r.georef.as_ref().map(|g| g.window(0, y0)),
            ..r.clone_meta()
        })
    }
}

impl Raster {
    /// Everything but the samples (an empty 0×0 raster with this one's metadata).
    pub(crate) fn clone_meta(&self) -> Raster {
        Raster {
            width: 0,
            height: 0,
            data: Vec::new(),
            mask: None,
            nodata: self.nodata,
            sample_type: self.sample_type,
            mapping: self.mapping,
            georef: self.georef.clone(),
            gdal_metadata: self.gdal_metadata.clone(),
        }
    }
}

impl RowSource for Raster {
    fn width(&self) -> usize {
        self.width
    }
    fn height(&self) -> usize {
        self.height
    }
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        InMemory(self).band(y0, rows)
    }
}

/// How many of `v` are true (a mask's valid samples, a bitmap's set ones): bytes summed 255
/// at a time, which the compiler vectorizes (a filtered count it does not: 7 instructions a
/// sample, on every decode with a mask or flat regions).
pub(crate) fn count_true(v: &[bool]) -> usize {
    v.chunks(255)
        .map(|c| c.iter().fold(0u8, |a, &b| a + u8::from(b)) as usize)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::count_true;
    use super::{OutputType, SampleType, ValueMapping};

    /// The output type rule, for every sample type and each kind of mapping.
    #[test]
    fn output_type_for_every_sample_type_and_mapping() {
        use SampleType::*;
        let m = |offset: f64, scale: f64| ValueMapping { scale, offset };
        let of = |st, mapping, nodata| OutputType::of(st, mapping, nodata);
        let id = ValueMapping::default();
        for st in [U8, I16, U16, I32, F32, F64] {
            assert_eq!(of(st, id, None), OutputType::Values(st));
        }
        // Floats are values whatever the mapping says.
        assert_eq!(of(F32, m(-32768.0, 1.0), None), OutputType::Values(F32));
        // Integer mappings: the smallest type holding offset + scale * [range] and nodata.
        assert_eq!(of(U16, m(-32768.0, 1.0), None), OutputType::Values(I16));
        assert_eq!(
            of(U16, m(-32768.0, 1.0), Some(-32768.0)),
            OutputType::Values(I16)
        );
        assert_eq!(
            of(U16, m(-32768.0, 1.0), Some(-99999.0)),
            OutputType::Values(I32)
        );
        assert_eq!(of(U8, m(-128.0, 1.0), None), OutputType::Values(I16));
        assert_eq!(of(U8, m(100.0, 1.0), None), OutputType::Values(I16));
        assert_eq!(of(U8, m(0.0, -1.0), None), OutputType::Values(I16));
        assert_eq!(of(I16, m(32768.0, 1.0), None), OutputType::Values(U16));
        assert_eq!(of(U16, m(1.0, 1.0), None), OutputType::Values(I32));
        assert_eq!(of(U16, m(0.0, -1.0), None), OutputType::Values(I32));
        // No type holds them: the codes with the offset.
        assert_eq!(
            of(I32, m(1.0, 1.0), None),
            OutputType::Codes(I32, m(1.0, 1.0))
        );
        // A scale or a fractional offset: the codes.
        for st in [U8, I16, U16, I32] {
            assert_eq!(
                of(st, m(0.0, 10.0), None),
                OutputType::Codes(st, m(0.0, 10.0))
            );
            assert_eq!(
                of(st, m(0.5, 1.0), None),
                OutputType::Codes(st, m(0.5, 1.0))
            );
            assert_eq!(
                of(st, m(-10.0, 0.1), Some(-10.0)),
                OutputType::Codes(st, m(-10.0, 0.1))
            );
            // A nodata value that is no code: float values.
            assert_eq!(of(st, m(0.0, 10.0), Some(5.0)), OutputType::Values(F64));
        }
        let c = OutputType::Codes(U16, m(-3276.8, 0.1));
        assert_eq!(c.stored(-3276.8 + 0.1 * 1234.0), 1234.0);
        assert!(c.stored(f64::NAN).is_nan());
        assert_eq!(OutputType::Values(I16).stored(-37.0), -37.0);
    }

    /// Every length around the 255-byte chunks, dense and sparse: the filtered count's result.
    #[test]
    fn count_true_is_the_filtered_count() {
        let mut rng = crate::testutil::Rng(12345);
        for n in [0usize, 1, 254, 255, 256, 510, 511, 1000, 4099] {
            for density in [0u64, 1, 50, 100] {
                let v: Vec<bool> = (0..n).map(|_| rng.below(100) < density).collect();
                assert_eq!(
                    count_true(&v),
                    v.iter().filter(|&&b| b).count(),
                    "n {n}, {density} %"
                );
            }
        }
    }
}
