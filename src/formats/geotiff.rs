//! GeoTIFF reading and writing: single-band elevation rasters with their georeferencing and nodata.
//!
//! Reading goes through the `tiff` crate's decoder, after a small pre-pass over the first
//! image file directory (IFD) of our own. The pre-pass checks that the tags the decoder will
//! read point inside the file, that the raster is of a layout we support (one sample per
//! pixel; uint8, int16, uint16, int32, float32 or float64; no compression, LZW, Deflate or
//! PackBits; predictor 1, 2 or 3) and that its size is within [`ReadOptions::max_samples`],
//! so garbage or hostile headers give an error instead of a large allocation.
//!
//! The GeoTIFF tags (ModelPixelScale, ModelTiepoint, ModelTransformation, the three GeoKey
//! tags and GDAL_NODATA) become a [`Georef`] with the GeoKeys kept verbatim, so a
//! GeoTIFF → raster → GeoTIFF round trip gives GDAL the same CRS.
//!
//! Writing produces a striped, Deflate-compressed GeoTIFF in the raster's sample type, with
//! the horizontal predictor for integer samples. (The `tiff` 0.11 encoder has no floating-point
//! predictor, so float samples are written with Deflate alone.)

use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{GeoKeys, Georef, Raster, RasterType, SampleType, check_size};
use std::io::{Cursor, Seek, Write};
use tiff::decoder::{Decoder, DecodingResult, Limits, ifd::Value};
use tiff::encoder::colortype::{
    ColorType, Gray8, Gray16, Gray32Float, Gray64Float, GrayI16, GrayI32,
};
use tiff::encoder::{
    Compression, DeflateLevel, DirectoryEncoder, Predictor, TiffEncoder, TiffKind, TiffKindBig,
    TiffKindStandard, TiffValue,
};
use tiff::tags::{Tag, Type};
use tiff::{Directory, TiffError};

// TIFF baseline / extension tags the pre-pass looks at.
const TAG_IMAGE_WIDTH: u16 = 256;
const TAG_IMAGE_LENGTH: u16 = 257;
const TAG_BITS_PER_SAMPLE: u16 = 258;
const TAG_COMPRESSION: u16 = 259;
const TAG_PHOTOMETRIC: u16 = 262;
const TAG_STRIP_OFFSETS: u16 = 273;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_ROWS_PER_STRIP: u16 = 278;
const TAG_STRIP_BYTE_COUNTS: u16 = 279;
const TAG_PLANAR_CONFIG: u16 = 284;
const TAG_PREDICTOR: u16 = 317;
const TAG_TILE_WIDTH: u16 = 322;
const TAG_TILE_LENGTH: u16 = 323;
const TAG_TILE_OFFSETS: u16 = 324;
const TAG_TILE_BYTE_COUNTS: u16 = 325;
const TAG_EXTRA_SAMPLES: u16 = 338;
const TAG_SAMPLE_FORMAT: u16 = 339;
const TAG_JPEG_TABLES: u16 = 347;
const TAG_YCBCR_SUBSAMPLING: u16 = 530;
// GeoTIFF and GDAL tags.
const TAG_MODEL_PIXEL_SCALE: u16 = 33550;
const TAG_MODEL_TIEPOINT: u16 = 33922;
const TAG_MODEL_TRANSFORMATION: u16 = 34264;
const TAG_GEO_KEY_DIRECTORY: u16 = 34735;
const TAG_GEO_DOUBLE_PARAMS: u16 = 34736;
const TAG_GEO_ASCII_PARAMS: u16 = 34737;
const TAG_GDAL_NODATA: u16 = 42113;

/// Tags whose data the pre-pass requires to lie inside the file (the ones the `tiff` decoder
/// or this module reads). Other tags are never read, so a broken one is harmless.
const CHECKED_TAGS: &[u16] = &[
    TAG_IMAGE_WIDTH,
    TAG_IMAGE_LENGTH,
    TAG_BITS_PER_SAMPLE,
    TAG_COMPRESSION,
    TAG_PHOTOMETRIC,
    TAG_STRIP_OFFSETS,
    TAG_SAMPLES_PER_PIXEL,
    TAG_ROWS_PER_STRIP,
    TAG_STRIP_BYTE_COUNTS,
    TAG_PLANAR_CONFIG,
    TAG_PREDICTOR,
    TAG_TILE_WIDTH,
    TAG_TILE_LENGTH,
    TAG_TILE_OFFSETS,
    TAG_TILE_BYTE_COUNTS,
    TAG_EXTRA_SAMPLES,
    TAG_SAMPLE_FORMAT,
    TAG_JPEG_TABLES,
    TAG_YCBCR_SUBSAMPLING,
    TAG_MODEL_PIXEL_SCALE,
    TAG_MODEL_TIEPOINT,
    TAG_MODEL_TRANSFORMATION,
    TAG_GEO_KEY_DIRECTORY,
    TAG_GEO_DOUBLE_PARAMS,
    TAG_GEO_ASCII_PARAMS,
    TAG_GDAL_NODATA,
];

// GeoKeys.
const KEY_MODEL_TYPE: u16 = 1024;
const KEY_RASTER_TYPE: u16 = 1025;
const KEY_GEOGRAPHIC_TYPE: u16 = 2048;
const KEY_PROJECTED_CS_TYPE: u16 = 3072;
const MODEL_TYPE_PROJECTED: u16 = 1;
const MODEL_TYPE_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_AREA: u16 = 1;
const RASTER_PIXEL_IS_POINT: u16 = 2;
const KEY_USER_DEFINED: u16 = 32767;

/// Target size of one uncompressed strip when writing. GDAL/libtiff default to 8 KiB strips;
/// 64 KiB keeps strips small enough for windowed reads while giving Deflate (32 KiB window)
/// enough context.
const STRIP_BYTES: u64 = 64 * 1024;

/// Above this many bytes of raw samples the writer switches to BigTIFF (classic TIFF offsets
/// are 32-bit).
const BIGTIFF_THRESHOLD: u64 = 3 << 30;

// ---------------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------------

/// Read a single-band GeoTIFF into a [`Raster`] (values exact as `f64`, nodata and NaN samples
/// marked invalid, georeferencing from the GeoTIFF tags).
pub fn read(bytes: &[u8], opts: &ReadOptions) -> Result<Raster> {
    let layout = precheck(bytes, opts)?;

    let mut limits = Limits::default();
    let image_bytes = (layout.samples as u64).saturating_mul(layout.sample_type.bits() as u64 / 8);
    limits.decoding_buffer_size = usize::try_from(image_bytes)
        .unwrap_or(usize::MAX)
        .max(Limits::default().decoding_buffer_size);
    // Chunk byte counts were checked against the file length, so the file length is a safe
    // bound for one compressed chunk (the default of 128 MiB would refuse large single-strip
    // files).
    limits.intermediate_buffer_size = bytes.len().max(Limits::default().intermediate_buffer_size);

    let mut dec = Decoder::new(Cursor::new(bytes))
        .map_err(tiff_err)?
        .with_limits(limits);
    let (w, h) = dec.dimensions().map_err(tiff_err)?;
    if (w as usize, h as usize) != (layout.width, layout.height) {
        return Err(Error::corrupt("GeoTIFF image size disagrees with its tags"));
    }

    let decoded = dec.read_image().map_err(tiff_err)?;
    let st = layout.sample_type;
    let data: Vec<f64> = match (decoded, st) {
        (DecodingResult::U8(v), SampleType::U8) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::I16(v), SampleType::I16) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::U16(v), SampleType::U16) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::I32(v), SampleType::I32) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::F32(v), SampleType::F32) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::F64(v), SampleType::F64) => v,
        _ => {
            return Err(Error::corrupt(format!(
                "GeoTIFF decoded to a different sample type than its tags declare ({})",
                st.name()
            )));
        }
    };
    if data.len() != layout.samples {
        return Err(Error::corrupt(format!(
            "GeoTIFF decoded to {} samples, expected {}",
            data.len(),
            layout.samples
        )));
    }

    let georef = read_georef(&mut dec)?;
    let nodata = read_nodata(&mut dec, st)?;

    let mut raster = Raster::from_values(layout.width, layout.height, data, nodata, st).map_err(
        |e| match e {
            Error::InvalidArgument { what } => Error::unsupported(format!(
                "GeoTIFF {what} (only finite values or nodata are supported)"
            )),
            other => other,
        },
    )?;
    raster.georef = georef;
    Ok(raster)
}

/// What the pre-pass found out about the first image.
struct Layout {
    width: usize,
    height: usize,
    samples: usize,
    sample_type: SampleType,
}

/// Byte order and offset size of a TIFF file, with bounds-checked readers.
struct RawTiff<'a> {
    b: &'a [u8],
    le: bool,
    big: bool,
}

/// One IFD entry as stored.
struct RawEntry {
    tag: u16,
    typ: u16,
    count: u64,
    /// Where the value bytes start (inline in the entry or at the offset it holds).
    data_pos: u64,
}

impl RawTiff<'_> {
    fn bytes(&self, pos: u64, len: usize) -> Option<&[u8]> {
        let pos = usize::try_from(pos).ok()?;
        self.b.get(pos..pos.checked_add(len)?)
    }
    fn u16_at(&self, pos: u64) -> Option<u16> {
        let s: [u8; 2] = self.bytes(pos, 2)?.try_into().ok()?;
        Some(if self.le {
            u16::from_le_bytes(s)
        } else {
            u16::from_be_bytes(s)
        })
    }
    fn u32_at(&self, pos: u64) -> Option<u32> {
        let s: [u8; 4] = self.bytes(pos, 4)?.try_into().ok()?;
        Some(if self.le {
            u32::from_le_bytes(s)
        } else {
            u32::from_be_bytes(s)
        })
    }
    fn u64_at(&self, pos: u64) -> Option<u64> {
        let s: [u8; 8] = self.bytes(pos, 8)?.try_into().ok()?;
        Some(if self.le {
            u64::from_le_bytes(s)
        } else {
            u64::from_be_bytes(s)
        })
    }

    /// The unsigned integer values of an entry of type BYTE, SHORT, LONG or LONG8.
    fn uints(&self, e: &RawEntry) -> Result<Vec<u64>> {
        let size = type_size(e.typ).unwrap_or(0);
        let bad = || {
            Error::corrupt(format!(
                "GeoTIFF tag {} has type {} where an unsigned integer is expected",
                e.tag, e.typ
            ))
        };
        // The data range was checked to lie inside the file, so `count` is bounded by its size.
        let mut out = Vec::with_capacity(e.count as usize);
        for k in 0..e.count {
            let pos = e.data_pos + k * size;
            let v = match e.typ {
                1 => self.bytes(pos, 1).map(|b| u64::from(b[0])),
                3 => self.u16_at(pos).map(u64::from),
                4 => self.u32_at(pos).map(u64::from),
                16 => self.u64_at(pos),
                _ => return Err(bad()),
            };
            out.push(v.ok_or_else(|| Error::corrupt("GeoTIFF is truncated"))?);
        }
        Ok(out)
    }
}

/// Size in bytes of one value of a TIFF field type.
fn type_size(typ: u16) -> Option<u64> {
    Some(match typ {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 | 16 | 17 | 18 => 8,
        _ => return None,
    })
}

/// Walk the first IFD: check that the tags we rely on are well-formed and inside the file,
/// that the layout is supported, and that the size is within the limit.
fn precheck(bytes: &[u8], opts: &ReadOptions) -> Result<Layout> {
    let truncated = || Error::corrupt("GeoTIFF is truncated");
    let le = match bytes.get(..2) {
        Some(b"II") => true,
        Some(b"MM") => false,
        Some(_) => return Err(Error::corrupt("not a TIFF file (bad byte-order mark)")),
        None => return Err(truncated()),
    };
    let mut t = RawTiff {
        b: bytes,
        le,
        big: false,
    };
    let ifd_pos = match t.u16_at(2).ok_or_else(truncated)? {
        42 => u64::from(t.u32_at(4).ok_or_else(truncated)?),
        43 => {
            t.big = true;
            if t.u16_at(4) != Some(8) || t.u16_at(6) != Some(0) {
                return Err(Error::corrupt("BigTIFF header is invalid"));
            }
            t.u64_at(8).ok_or_else(truncated)?
        }
        v => return Err(Error::corrupt(format!("not a TIFF file (version {v})"))),
    };
    if ifd_pos < 8 || ifd_pos >= bytes.len() as u64 {
        return Err(Error::corrupt(format!(
            "GeoTIFF image directory offset {ifd_pos} is outside the file ({} bytes)",
            bytes.len()
        )));
    }
    let (count, entry_size, first, inline) = if t.big {
        (
            t.u64_at(ifd_pos).ok_or_else(truncated)?,
            20u64,
            ifd_pos + 8,
            8u64,
        )
    } else {
        let n = u64::from(t.u16_at(ifd_pos).ok_or_else(truncated)?);
        (n, 12u64, ifd_pos + 2, 4u64)
    };
    if count == 0 {
        return Err(Error::corrupt("GeoTIFF image directory is empty"));
    }
    let dir_end = count
        .checked_mul(entry_size)
        .and_then(|n| n.checked_add(first))
        .ok_or_else(truncated)?;
    if dir_end > bytes.len() as u64 {
        return Err(truncated());
    }

    let mut entries: Vec<RawEntry> = Vec::new();
    for k in 0..count {
        let p = first + k * entry_size;
        let tag = t.u16_at(p).ok_or_else(truncated)?;
        if !CHECKED_TAGS.contains(&tag) {
            continue;
        }
        let typ = t.u16_at(p + 2).ok_or_else(truncated)?;
        let (cnt, field) = if t.big {
            (t.u64_at(p + 4).ok_or_else(truncated)?, p + 12)
        } else {
            (u64::from(t.u32_at(p + 4).ok_or_else(truncated)?), p + 8)
        };
        let size = type_size(typ).ok_or_else(|| {
            Error::corrupt(format!("GeoTIFF tag {tag} has an unknown field type {typ}"))
        })?;
        let len = size.checked_mul(cnt).ok_or_else(truncated)?;
        let data_pos = if len <= inline {
            field
        } else if t.big {
            t.u64_at(field).ok_or_else(truncated)?
        } else {
            u64::from(t.u32_at(field).ok_or_else(truncated)?)
        };
        if data_pos
            .checked_add(len)
            .is_none_or(|end| end > bytes.len() as u64)
        {
            return Err(Error::corrupt(format!(
                "GeoTIFF is truncated or corrupt: tag {tag} ({cnt} values at offset {data_pos}) \
                 ends past the end of the file ({} bytes)",
                bytes.len()
            )));
        }
        if entries.iter().any(|e| e.tag == tag) {
            continue; // the decoder keeps the first one too
        }
        entries.push(RawEntry {
            tag,
            typ,
            count: cnt,
            data_pos,
        });
    }
    let find = |tag: u16| entries.iter().find(|e| e.tag == tag);
    let uints = |tag: u16| -> Result<Option<Vec<u64>>> {
        match find(tag) {
            None => Ok(None),
            Some(e) => {
                let v = t.uints(e)?;
                if v.is_empty() {
                    return Err(Error::corrupt(format!("GeoTIFF tag {tag} has no value")));
                }
                Ok(Some(v))
            }
        }
    };
    let scalar = |tag: u16| -> Result<Option<u64>> { Ok(uints(tag)?.map(|v| v[0])) };

    let width =
        scalar(TAG_IMAGE_WIDTH)?.ok_or_else(|| Error::corrupt("GeoTIFF has no ImageWidth tag"))?;
    let height = scalar(TAG_IMAGE_LENGTH)?
        .ok_or_else(|| Error::corrupt("GeoTIFF has no ImageLength tag"))?;
    if width == 0 || height == 0 {
        return Err(Error::corrupt(format!(
            "GeoTIFF image size {width}x{height} is empty"
        )));
    }

    // Layout: one sample per pixel of a supported type.
    let spp = scalar(TAG_SAMPLES_PER_PIXEL)?.unwrap_or(1);
    if spp != 1 {
        return Err(Error::unsupported(format!(
            "GeoTIFF with {spp} samples per pixel (only single-band rasters are supported)"
        )));
    }
    match scalar(TAG_PHOTOMETRIC)? {
        Some(1) => {}
        Some(p) => {
            let name = match p {
                0 => "WhiteIsZero",
                2 => "RGB",
                3 => "palette",
                4 => "transparency mask",
                5 => "CMYK",
                6 => "YCbCr",
                8..=10 => "CIE Lab",
                _ => "unknown",
            };
            return Err(Error::unsupported(format!(
                "GeoTIFF with {name} photometric interpretation ({p}) (only grey-scale \
                 BlackIsZero rasters are supported)"
            )));
        }
        None => {
            return Err(Error::unsupported(
                "GeoTIFF without a PhotometricInterpretation tag (the TIFF decoder requires it)",
            ));
        }
    }
    let bits = scalar(TAG_BITS_PER_SAMPLE)?.unwrap_or(1);
    let format = scalar(TAG_SAMPLE_FORMAT)?.unwrap_or(1);
    if ![8, 16, 32, 64].contains(&bits) {
        return Err(Error::unsupported(format!(
            "GeoTIFF with {bits} bits per sample (only 8, 16, 32 and 64 are supported)"
        )));
    }
    let sample_type = match (format, bits) {
        (1, 8) => SampleType::U8,
        (1, 16) => SampleType::U16,
        (2, 16) => SampleType::I16,
        (2, 32) => SampleType::I32,
        (3, 32) => SampleType::F32,
        (3, 64) => SampleType::F64,
        _ => {
            let kind = match format {
                1 => "uint",
                2 => "int",
                3 => "float",
                4 => "untyped (void) ",
                5 => "complex int",
                6 => "complex float",
                _ => "unknown-format ",
            };
            return Err(Error::unsupported(format!(
                "GeoTIFF with {kind}{bits} samples (supported: uint8, int16, uint16, int32, \
                 float32, float64)"
            )));
        }
    };
    let compression = scalar(TAG_COMPRESSION)?.unwrap_or(1);
    match compression {
        1 | 5 | 8 | 32946 | 32773 => {}
        c => {
            let name = match c {
                2 => "CCITT RLE",
                3 | 4 => "CCITT fax",
                6 | 7 => "JPEG",
                34712 => "JPEG 2000",
                34887 => "LERC",
                34925 => "LZMA",
                50000 => "Zstandard",
                50001 => "WebP",
                _ => "unknown",
            };
            return Err(Error::unsupported(format!(
                "GeoTIFF with {name} compression ({c}) (supported: none, LZW, Deflate, PackBits)"
            )));
        }
    }
    match scalar(TAG_PREDICTOR)?.unwrap_or(1) {
        1 | 2 => {}
        3 if !sample_type.is_integer() => {}
        3 => {
            return Err(Error::unsupported(format!(
                "GeoTIFF with the floating-point predictor (3) on {} samples",
                sample_type.name()
            )));
        }
        p => return Err(Error::unsupported(format!("GeoTIFF with predictor {p}"))),
    }
    match scalar(TAG_PLANAR_CONFIG)?.unwrap_or(1) {
        1 | 2 => {}
        p => {
            return Err(Error::corrupt(format!(
                "GeoTIFF has an invalid PlanarConfiguration {p}"
            )));
        }
    }

    let max = opts.max_samples();
    let samples = check_size(width, height, max)?;

    // Chunk layout: every strip / tile must lie inside the file.
    let tiled = find(TAG_TILE_OFFSETS).is_some() || find(TAG_TILE_WIDTH).is_some();
    let (offsets_tag, counts_tag, expected) = if tiled {
        let tw = scalar(TAG_TILE_WIDTH)?.unwrap_or(0);
        let th = scalar(TAG_TILE_LENGTH)?.unwrap_or(0);
        if tw == 0 || th == 0 {
            return Err(Error::corrupt(format!(
                "GeoTIFF tile size {tw}x{th} is invalid"
            )));
        }
        if tw.saturating_mul(th) > max {
            return Err(Error::limit(format!(
                "GeoTIFF tile of {tw}x{th} samples is over the limit of {max}"
            )));
        }
        let n = width.div_ceil(tw).saturating_mul(height.div_ceil(th));
        (TAG_TILE_OFFSETS, TAG_TILE_BYTE_COUNTS, n)
    } else {
        let rps = scalar(TAG_ROWS_PER_STRIP)?
            .unwrap_or(height)
            .clamp(1, height);
        (
            TAG_STRIP_OFFSETS,
            TAG_STRIP_BYTE_COUNTS,
            height.div_ceil(rps),
        )
    };
    let offsets = uints(offsets_tag)?
        .ok_or_else(|| Error::corrupt("GeoTIFF has no strip or tile offsets"))?;
    let counts = uints(counts_tag)?
        .ok_or_else(|| Error::corrupt("GeoTIFF has no strip or tile byte counts"))?;
    if offsets.len() != counts.len() || (offsets.len() as u64) < expected {
        return Err(Error::corrupt(format!(
            "GeoTIFF has {} chunk offsets and {} byte counts for {expected} chunks",
            offsets.len(),
            counts.len()
        )));
    }
    for (i, (&o, &c)) in offsets.iter().zip(&counts).enumerate() {
        if o.checked_add(c).is_none_or(|end| end > bytes.len() as u64) {
            return Err(Error::corrupt(format!(
                "GeoTIFF is truncated: {} {i} ({c} bytes at offset {o}) ends past the end of \
                 the file ({} bytes)",
                if tiled { "tile" } else { "strip" },
                bytes.len()
            )));
        }
    }

    Ok(Layout {
        width: width as usize,
        height: height as usize,
        samples,
        sample_type,
    })
}

/// Map a `tiff` crate error to ours.
fn tiff_err(e: TiffError) -> Error {
    match e {
        TiffError::UnsupportedError(u) => Error::unsupported(format!("GeoTIFF: {u}")),
        TiffError::LimitsExceeded => {
            Error::limit("GeoTIFF: the TIFF decoder's limits were exceeded")
        }
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::corrupt("GeoTIFF is truncated")
        }
        other => Error::corrupt(format!("GeoTIFF: {other}")),
    }
}

type Dec<'a> = Decoder<Cursor<&'a [u8]>>;

fn scalar_f64(v: Value) -> Option<f64> {
    Some(match v {
        Value::Double(x) => x,
        Value::Float(x) => f64::from(x),
        Value::Byte(x) => f64::from(x),
        Value::Short(x) => f64::from(x),
        Value::SignedShort(x) => f64::from(x),
        Value::Unsigned(x) => f64::from(x),
        Value::Signed(x) => f64::from(x),
        _ => return None,
    })
}

/// A numeric tag as doubles (GeoTIFF tags are DOUBLE; FLOAT and integers are accepted too).
fn tag_f64s(dec: &mut Dec<'_>, tag: u16) -> Result<Option<Vec<f64>>> {
    let Some(v) = dec
        .find_tag(Tag::from_u16_exhaustive(tag))
        .map_err(tiff_err)?
    else {
        return Ok(None);
    };
    let bad = || Error::corrupt(format!("GeoTIFF tag {tag} does not hold numbers"));
    let out = match v {
        Value::List(l) => l
            .into_iter()
            .map(scalar_f64)
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(bad)?,
        other => vec![scalar_f64(other).ok_or_else(bad)?],
    };
    if out.iter().any(|x| !x.is_finite()) {
        return Err(Error::corrupt(format!(
            "GeoTIFF tag {tag} holds a non-finite number"
        )));
    }
    Ok(Some(out))
}

fn tag_string(dec: &mut Dec<'_>, tag: u16) -> Result<Option<String>> {
    match dec
        .find_tag(Tag::from_u16_exhaustive(tag))
        .map_err(tiff_err)?
    {
        None => Ok(None),
        Some(Value::Ascii(s)) => Ok(Some(s)),
        Some(_) => Err(Error::corrupt(format!(
            "GeoTIFF tag {tag} is not an ASCII string"
        ))),
    }
}

/// Value of a GeoKey stored directly in the directory (TIFFTagLocation 0).
fn geokey_short(dir: &[u16], key: u16) -> Option<u16> {
    let n = usize::from(*dir.get(3)?);
    dir.get(4..)?
        .chunks_exact(4)
        .take(n)
        .find(|k| k[0] == key && k[1] == 0)
        .map(|k| k[3])
}

fn read_georef(dec: &mut Dec<'_>) -> Result<Option<Georef>> {
    let scale = tag_f64s(dec, TAG_MODEL_PIXEL_SCALE)?;
    let tie = tag_f64s(dec, TAG_MODEL_TIEPOINT)?;
    let transform = tag_f64s(dec, TAG_MODEL_TRANSFORMATION)?;
    let directory = match dec.find_tag(Tag::GeoKeyDirectoryTag).map_err(tiff_err)? {
        None => None,
        Some(v) => Some(
            v.into_u16_vec()
                .map_err(|_| Error::corrupt("GeoTIFF GeoKeyDirectoryTag does not hold shorts"))?,
        ),
    };
    let geokeys = match directory {
        None => None,
        Some(directory) => {
            if directory.len() < 4 {
                return Err(Error::corrupt(format!(
                    "GeoTIFF GeoKeyDirectoryTag has {} values, fewer than its 4-value header",
                    directory.len()
                )));
            }
            let doubles = tag_f64s(dec, TAG_GEO_DOUBLE_PARAMS)?.unwrap_or_default();
            let ascii = tag_string(dec, TAG_GEO_ASCII_PARAMS)?.unwrap_or_default();
            Some(GeoKeys {
                directory,
                doubles,
                ascii,
            })
        }
    };

    let placement = match (&scale, &tie, &transform) {
        (Some(s), Some(t), _) => {
            if s.len() < 2 || t.len() < 6 {
                return Err(Error::corrupt(format!(
                    "GeoTIFF ModelPixelScale ({} values) or ModelTiepoint ({} values) is too short",
                    s.len(),
                    t.len()
                )));
            }
            let (sx, sy) = (s[0], s[1]);
            let (i, j, x, y) = (t[0], t[1], t[3], t[4]);
            Some(([x - i * sx, y + j * sy], [sx, sy]))
        }
        (None, None, Some(m)) | (Some(_), None, Some(m)) | (None, Some(_), Some(m)) => {
            if m.len() < 16 {
                return Err(Error::corrupt(format!(
                    "GeoTIFF ModelTransformation has {} values, expected 16",
                    m.len()
                )));
            }
            if m[1] != 0.0 || m[4] != 0.0 {
                return Err(Error::unsupported(
                    "GeoTIFF with a rotated or sheared ModelTransformation (only north-up \
                     rasters are supported)",
                ));
            }
            Some(([m[3], m[7]], [m[0], -m[5]]))
        }
        (None, Some(t), None) => {
            return Err(Error::unsupported(format!(
                "GeoTIFF georeferenced by {} tiepoint(s) without a pixel scale (ground control \
                 points are not supported)",
                t.len() / 6
            )));
        }
        (Some(_), None, None) => {
            return Err(Error::unsupported(
                "GeoTIFF with a ModelPixelScale but no ModelTiepoint",
            ));
        }
        (None, None, None) => None,
    };
    let (origin, pixel_size) = match (placement, &geokeys) {
        (Some(p), _) => p,
        (None, Some(_)) => ([0.0, 0.0], [1.0, 1.0]),
        (None, None) => return Ok(None),
    };

    let dir: &[u16] = geokeys.as_ref().map_or(&[], |k| &k.directory);
    let raster_type = match geokey_short(dir, KEY_RASTER_TYPE) {
        Some(RASTER_PIXEL_IS_POINT) => RasterType::Point,
        _ => RasterType::Area,
    };
    let usable = |v: u16| v != 0 && v != KEY_USER_DEFINED;
    let epsg = match geokey_short(dir, KEY_PROJECTED_CS_TYPE) {
        Some(v) => usable(v).then_some(u32::from(v)),
        None if geokey_short(dir, KEY_MODEL_TYPE) == Some(MODEL_TYPE_PROJECTED) => None,
        None => geokey_short(dir, KEY_GEOGRAPHIC_TYPE)
            .filter(|&v| usable(v))
            .map(u32::from),
    };
    Ok(Some(Georef {
        origin,
        pixel_size,
        raster_type,
        epsg,
        wkt: None,
        geokeys,
    }))
}

/// Parse a GDAL_NODATA string ("-9999", "nan", "-3.40282346638529e+38", ...).
fn parse_nodata(s: &str) -> Option<f64> {
    let t = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    if let Ok(v) = t.parse::<f64>() {
        return Some(v);
    }
    let l = t.to_ascii_lowercase();
    let l = l.trim_start_matches(['+', '-']);
    (l == "nan" || l.contains("#qnan") || l.contains("#ind")).then_some(f64::NAN)
}

/// The declared nodata value, as the samples hold it (f32-rounded for float32 rasters).
/// A NaN nodata is no nodata: NaN samples are invalid anyway.
fn read_nodata(dec: &mut Dec<'_>, st: SampleType) -> Result<Option<f64>> {
    let Some(s) = tag_string(dec, TAG_GDAL_NODATA)? else {
        return Ok(None);
    };
    if s.trim_matches(|c: char| c == '\0' || c.is_whitespace())
        .is_empty()
    {
        return Ok(None);
    }
    let v = parse_nodata(&s).ok_or_else(|| {
        Error::corrupt(format!(
            "GeoTIFF GDAL_NODATA tag '{}' is not a number",
            s.trim()
        ))
    })?;
    if v.is_nan() {
        return Ok(None);
    }
    Ok(Some(if st == SampleType::F32 {
        f64::from(v as f32)
    } else {
        v
    }))
}

// ---------------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------------

/// Write a raster as a striped, Deflate-compressed single-band GeoTIFF.
///
/// Samples are written in the raster's sample type, except that an integer raster with a
/// non-identity value mapping is written as float32 (or float64 when float32 would not hold
/// its values exactly), since a GeoTIFF stores physical values. Integer samples are rounded
/// to the nearest integer; out-of-range values are an error.
pub fn write(r: &Raster) -> Result<Vec<u8>> {
    r.validate()?;
    let too_big = || {
        Error::invalid(format!(
            "raster {}x{} is too large for a TIFF",
            r.width, r.height
        ))
    };
    let width = u32::try_from(r.width).map_err(|_| too_big())?;
    let height = u32::try_from(r.height).map_err(|_| too_big())?;
    let has_invalid = r.mask.as_ref().is_some_and(|m| m.contains(&false));
    let st = output_type(r);

    let mut tags = geo_tags(r.georef.as_ref())?;
    let size = (width, height);
    match st {
        SampleType::F32 => {
            let fill = r.nodata.map_or(f32::NAN, |nd| nd as f32);
            let mut data = Vec::with_capacity(r.len());
            for (i, &v) in r.data.iter().enumerate() {
                if r.is_valid(i) {
                    let x = v as f32;
                    if !x.is_finite() {
                        return Err(Error::invalid(format!(
                            "sample {v} at row {}, col {} overflows float32",
                            i / r.width,
                            i % r.width
                        )));
                    }
                    data.push(x);
                } else {
                    data.push(fill);
                }
            }
            tags.nodata = match r.nodata {
                Some(nd) => Some(f64::from(nd as f32)),
                None => has_invalid.then_some(f64::NAN),
            };
            encode::<Gray32Float>(size, &data, Predictor::None, &tags)
        }
        SampleType::F64 => {
            let fill = r.nodata.unwrap_or(f64::NAN);
            let data: Vec<f64> = (0..r.len())
                .map(|i| if r.is_valid(i) { r.data[i] } else { fill })
                .collect();
            tags.nodata = r.nodata.or(has_invalid.then_some(f64::NAN));
            encode::<Gray64Float>(size, &data, Predictor::None, &tags)
        }
        _ => {
            let (codes, nodata) = integer_codes(r, st, has_invalid)?;
            tags.nodata = nodata;
            let h = Predictor::Horizontal;
            match st {
                SampleType::U8 => {
                    let d: Vec<u8> = codes.iter().map(|&c| c as u8).collect();
                    encode::<Gray8>(size, &d, h, &tags)
                }
                SampleType::I16 => {
                    let d: Vec<i16> = codes.iter().map(|&c| c as i16).collect();
                    encode::<GrayI16>(size, &d, h, &tags)
                }
                SampleType::U16 => {
                    let d: Vec<u16> = codes.iter().map(|&c| c as u16).collect();
                    encode::<Gray16>(size, &d, h, &tags)
                }
                _ => {
                    let d: Vec<i32> = codes.iter().map(|&c| c as i32).collect();
                    encode::<GrayI32>(size, &d, h, &tags)
                }
            }
        }
    }
}

/// The sample type to write: the raster's own, except float for mapped integer rasters.
fn output_type(r: &Raster) -> SampleType {
    if !r.sample_type.is_integer() || r.mapping.is_identity() {
        return r.sample_type;
    }
    let exact_f32 = |v: f64| f64::from(v as f32) == v;
    let all_f32 = (0..r.len()).all(|i| !r.is_valid(i) || exact_f32(r.data[i]))
        && r.nodata.is_none_or(exact_f32);
    if all_f32 {
        SampleType::F32
    } else {
        SampleType::F64
    }
}

/// Integer codes of every sample (valid ones rounded, invalid ones the fill value) and the
/// nodata value to declare.
fn integer_codes(r: &Raster, st: SampleType, has_invalid: bool) -> Result<(Vec<i64>, Option<f64>)> {
    let (lo, hi) = st
        .int_range()
        .ok_or_else(|| Error::invalid(format!("{} is not an integer type", st.name())))?;
    let fits = |c: f64| c >= lo && c <= hi;
    let fill = match (r.nodata, has_invalid) {
        (Some(nd), true) => {
            if nd.fract() != 0.0 || !fits(nd) {
                return Err(Error::invalid(format!(
                    "nodata value {nd} cannot be stored in a {} GeoTIFF",
                    st.name()
                )));
            }
            nd
        }
        (Some(_), false) | (None, false) => 0.0,
        (None, true) => {
            // No declared nodata: use the type's minimum (maximum for unsigned types), or the
            // other end of the range if a valid sample already holds that value.
            let prefer = if matches!(st, SampleType::U8 | SampleType::U16) {
                [hi, lo]
            } else {
                [lo, hi]
            };
            let used = |c: f64| (0..r.len()).any(|i| r.is_valid(i) && r.data[i].round() == c);
            prefer.into_iter().find(|&c| !used(c)).ok_or_else(|| {
                Error::invalid(format!(
                    "raster has nodata samples but no nodata value, and both ends of the {} \
                     range are used by valid samples",
                    st.name()
                ))
            })?
        }
    };
    let mut codes = Vec::with_capacity(r.len());
    for (i, &v) in r.data.iter().enumerate() {
        if !r.is_valid(i) {
            codes.push(fill as i64);
            continue;
        }
        let c = v.round();
        if !fits(c) {
            return Err(Error::invalid(format!(
                "sample {v} at row {}, col {} does not fit in {} ({lo}..={hi})",
                i / r.width,
                i % r.width,
                st.name()
            )));
        }
        codes.push(c as i64);
    }
    let nodata = match r.nodata {
        Some(nd) => Some(nd),
        None => has_invalid.then_some(fill),
    };
    Ok((codes, nodata))
}

/// The GeoTIFF tags to write besides the image structure.
#[derive(Default)]
struct GeoTags {
    pixel_scale: Option<[f64; 3]>,
    tiepoint: Option<[f64; 6]>,
    key_directory: Option<Vec<u16>>,
    key_doubles: Vec<f64>,
    key_ascii: String,
    /// GDAL_NODATA (NaN is written as "nan").
    nodata: Option<f64>,
}

fn geo_tags(georef: Option<&Georef>) -> Result<GeoTags> {
    let mut tags = GeoTags::default();
    let Some(g) = georef else {
        return Ok(tags);
    };
    if g.origin.iter().chain(&g.pixel_size).any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "georeferencing has a non-finite origin or pixel size",
        ));
    }
    tags.pixel_scale = Some([g.pixel_size[0], g.pixel_size[1], 0.0]);
    tags.tiepoint = Some([0.0, 0.0, 0.0, g.origin[0], g.origin[1], 0.0]);
    let raster_type = match g.raster_type {
        RasterType::Area => RASTER_PIXEL_IS_AREA,
        RasterType::Point => RASTER_PIXEL_IS_POINT,
    };
    match &g.geokeys {
        Some(k) => {
            let mut dir = k.directory.clone();
            set_raster_type_key(&mut dir, raster_type)?;
            tags.key_directory = Some(dir);
            tags.key_doubles = k.doubles.clone();
            tags.key_ascii = k.ascii.clone();
        }
        None => tags.key_directory = synth_geokeys(g.epsg, raster_type),
    }
    Ok(tags)
}

/// Make GTRasterTypeGeoKey in a verbatim directory agree with the raster type. A missing key
/// means PixelIsArea, so it is only added for PixelIsPoint.
fn set_raster_type_key(dir: &mut Vec<u16>, raster_type: u16) -> Result<()> {
    let bad = || Error::invalid("GeoKey directory is malformed");
    let n = usize::from(*dir.get(3).ok_or_else(bad)?);
    let keys_end = 4 + 4 * n;
    if dir.len() < keys_end {
        return Err(bad());
    }
    let mut insert_at = keys_end;
    for k in 0..n {
        let p = 4 + 4 * k;
        if dir[p] == KEY_RASTER_TYPE {
            dir[p + 1] = 0;
            dir[p + 2] = 1;
            dir[p + 3] = raster_type;
            return Ok(());
        }
        if dir[p] > KEY_RASTER_TYPE && insert_at == keys_end {
            insert_at = p;
        }
    }
    if raster_type == RASTER_PIXEL_IS_AREA {
        return Ok(());
    }
    dir[3] = u16::try_from(n + 1).map_err(|_| bad())?;
    dir.splice(insert_at..insert_at, [KEY_RASTER_TYPE, 0, 1, raster_type]);
    Ok(())
}

/// A minimal GeoKey directory for an EPSG code and raster type; None when there is nothing to
/// say (no EPSG code and PixelIsArea, the default).
fn synth_geokeys(epsg: Option<u32>, raster_type: u16) -> Option<Vec<u16>> {
    let code = epsg.and_then(|e| u16::try_from(e).ok());
    if code.is_none() && raster_type == RASTER_PIXEL_IS_AREA {
        return None;
    }
    let mut keys: Vec<[u16; 4]> = Vec::new();
    if let Some(code) = code {
        let geographic = (4000..5000).contains(&code);
        let model = if geographic {
            MODEL_TYPE_GEOGRAPHIC
        } else {
            MODEL_TYPE_PROJECTED
        };
        keys.push([KEY_MODEL_TYPE, 0, 1, model]);
        keys.push([KEY_RASTER_TYPE, 0, 1, raster_type]);
        let key = if geographic {
            KEY_GEOGRAPHIC_TYPE
        } else {
            KEY_PROJECTED_CS_TYPE
        };
        keys.push([key, 0, 1, code]);
    } else {
        keys.push([KEY_RASTER_TYPE, 0, 1, raster_type]);
    }
    let mut dir = vec![1, 1, 0, keys.len() as u16];
    dir.extend(keys.into_iter().flatten());
    Some(dir)
}

/// GDAL_NODATA text that parses back to exactly `v`.
fn format_nodata(v: f64) -> String {
    if v.is_nan() {
        "nan".to_string()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_string()
    } else if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v:?}")
    }
}

fn enc_err(e: TiffError) -> Error {
    Error::invalid(format!("GeoTIFF encoding failed: {e}"))
}

fn encode<C>(
    size: (u32, u32),
    data: &[C::Inner],
    predictor: Predictor,
    tags: &GeoTags,
) -> Result<Vec<u8>>
where
    C: ColorType,
    [C::Inner]: TiffValue,
{
    let raw = (data.len() as u64).saturating_mul(u64::from(<C::Inner as TiffValue>::BYTE_LEN));
    if raw > BIGTIFF_THRESHOLD {
        encode_kind::<C, TiffKindBig>(size, data, predictor, tags)
    } else {
        encode_kind::<C, TiffKindStandard>(size, data, predictor, tags)
    }
}

fn encode_kind<C, K>(
    (width, height): (u32, u32),
    data: &[C::Inner],
    predictor: Predictor,
    tags: &GeoTags,
) -> Result<Vec<u8>>
where
    C: ColorType,
    [C::Inner]: TiffValue,
    K: TiffKind,
{
    let row_bytes = u64::from(width) * u64::from(<C::Inner as TiffValue>::BYTE_LEN);
    let rows_per_strip = (STRIP_BYTES / row_bytes).clamp(1, u64::from(height)) as u32;
    let mut out = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::<_, K>::new_generic(&mut out)
            .map_err(enc_err)?
            .with_compression(Compression::Deflate(DeflateLevel::Balanced))
            .with_predictor(predictor);
        let mut image = enc.new_image::<C>(width, height).map_err(enc_err)?;
        image.rows_per_strip(rows_per_strip).map_err(enc_err)?;
        write_geo_tags(image.encoder(), tags)?;
        // `write_data` (not `write_strip`) is what switches the compressor on.
        image.write_data(data).map_err(enc_err)?;
    }
    Ok(out.into_inner())
}

fn write_geo_tags<W: Write + Seek, K: TiffKind>(
    e: &mut DirectoryEncoder<'_, W, K>,
    tags: &GeoTags,
) -> Result<()> {
    if let Some(s) = &tags.pixel_scale {
        e.write_tag(Tag::ModelPixelScaleTag, &s[..])
            .map_err(enc_err)?;
    }
    if let Some(t) = &tags.tiepoint {
        e.write_tag(Tag::ModelTiepointTag, &t[..])
            .map_err(enc_err)?;
    }
    if let Some(d) = &tags.key_directory {
        e.write_tag(Tag::GeoKeyDirectoryTag, &d[..])
            .map_err(enc_err)?;
        if !tags.key_doubles.is_empty() {
            e.write_tag(Tag::GeoDoubleParamsTag, &tags.key_doubles[..])
                .map_err(enc_err)?;
        }
        if !tags.key_ascii.is_empty() {
            write_ascii(e, Tag::GeoAsciiParamsTag, &tags.key_ascii)?;
        }
    }
    if let Some(nd) = tags.nodata {
        write_ascii(e, Tag::GdalNodata, &format_nodata(nd))?;
    }
    Ok(())
}

/// Write an ASCII tag with its trailing NUL. Unlike `write_tag(tag, &str)`, this accepts
/// non-ASCII UTF-8 text (which the reader gives back as it was), so verbatim GeoAsciiParams
/// with e.g. accented citations survive a round trip.
fn write_ascii<W: Write + Seek, K: TiffKind>(
    e: &mut DirectoryEncoder<'_, W, K>,
    tag: Tag,
    s: &str,
) -> Result<()> {
    if s.contains('\0') {
        return Err(Error::invalid(format!(
            "text for TIFF tag {} contains a NUL character",
            tag.to_u16()
        )));
    }
    let mut b = Vec::with_capacity(s.len() + 1);
    b.extend_from_slice(s.as_bytes());
    b.push(0);
    let entry = e.write_entry_bytes(Type::ASCII, &b).map_err(enc_err)?;
    let mut dir = Directory::empty();
    dir.extend([(tag, entry)]);
    e.extend_from(&dir);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ValueMapping;
    use crate::testutil::{Rng, corpus};

    const CORPUS_TIFS: &[&str] = &[
        "pysheds_dem_texas",
        "srtm30m_bigtujunga_utm11",
        "terra_elev_luxembourg",
        "terra_elev_vinschgau",
    ];

    fn opts() -> ReadOptions {
        ReadOptions::default()
    }

    /// Same raster, comparing floats by bits (NaN fill values included).
    fn assert_same(a: &Raster, b: &Raster, what: &str) {
        assert_eq!((a.width, a.height), (b.width, b.height), "{what}: size");
        assert_eq!(a.sample_type, b.sample_type, "{what}: sample type");
        assert_eq!(a.mask, b.mask, "{what}: mask");
        assert_eq!(
            a.nodata.map(f64::to_bits),
            b.nodata.map(f64::to_bits),
            "{what}: nodata"
        );
        assert_eq!(a.mapping, b.mapping, "{what}: mapping");
        assert_eq!(a.georef, b.georef, "{what}: georef");
        let differing = a
            .data
            .iter()
            .zip(&b.data)
            .position(|(x, y)| x.to_bits() != y.to_bits());
        assert_eq!(differing, None, "{what}: first differing sample");
    }

    /// Hand-built classic TIFF: pixel data at offset 8, then the IFD, then long tag values.
    struct Builder {
        le: bool,
        entries: Vec<(u16, u16, u32, Vec<u8>)>,
    }

    impl Builder {
        fn new(le: bool) -> Self {
            Builder {
                le,
                entries: Vec::new(),
            }
        }
        fn set(&mut self, tag: u16, typ: u16, count: u32, bytes: Vec<u8>) -> &mut Self {
            self.entries.retain(|e| e.0 != tag);
            self.entries.push((tag, typ, count, bytes));
            self
        }
        fn remove(&mut self, tag: u16) -> &mut Self {
            self.entries.retain(|e| e.0 != tag);
            self
        }
        fn short(&mut self, tag: u16, v: &[u16]) -> &mut Self {
            let le = self.le;
            let b = v
                .iter()
                .flat_map(|x| if le { x.to_le_bytes() } else { x.to_be_bytes() })
                .collect();
            self.set(tag, 3, v.len() as u32, b)
        }
        fn long(&mut self, tag: u16, v: &[u32]) -> &mut Self {
            let le = self.le;
            let b = v
                .iter()
                .flat_map(|x| if le { x.to_le_bytes() } else { x.to_be_bytes() })
                .collect();
            self.set(tag, 4, v.len() as u32, b)
        }
        fn double(&mut self, tag: u16, v: &[f64]) -> &mut Self {
            let le = self.le;
            let b = v
                .iter()
                .flat_map(|x| if le { x.to_le_bytes() } else { x.to_be_bytes() })
                .collect();
            self.set(tag, 12, v.len() as u32, b)
        }
        fn ascii(&mut self, tag: u16, s: &str) -> &mut Self {
            let mut b = s.as_bytes().to_vec();
            b.push(0);
            let n = b.len() as u32;
            self.set(tag, 2, n, b)
        }
        /// The usual tags of a single-strip, uncompressed, single-band image.
        fn basic(le: bool, w: u32, h: u32, bits: u16, format: u16, data_len: usize) -> Self {
            let mut b = Builder::new(le);
            b.long(TAG_IMAGE_WIDTH, &[w])
                .long(TAG_IMAGE_LENGTH, &[h])
                .short(TAG_BITS_PER_SAMPLE, &[bits])
                .short(TAG_COMPRESSION, &[1])
                .short(TAG_PHOTOMETRIC, &[1])
                .long(TAG_STRIP_OFFSETS, &[8])
                .short(TAG_SAMPLES_PER_PIXEL, &[1])
                .long(TAG_ROWS_PER_STRIP, &[h])
                .long(TAG_STRIP_BYTE_COUNTS, &[data_len as u32])
                .short(TAG_SAMPLE_FORMAT, &[format]);
            b
        }
        fn build(&self, data: &[u8]) -> Vec<u8> {
            let le = self.le;
            let u16b = |v: u16| if le { v.to_le_bytes() } else { v.to_be_bytes() };
            let u32b = |v: u32| if le { v.to_le_bytes() } else { v.to_be_bytes() };
            let mut entries = self.entries.clone();
            entries.sort_by_key(|e| e.0);
            let ifd = (8 + data.len() + data.len() % 2) as u32;
            let mut extra_at = ifd + 2 + 12 * entries.len() as u32 + 4;
            let mut out = Vec::new();
            out.extend_from_slice(if le { b"II" } else { b"MM" });
            out.extend_from_slice(&u16b(42));
            out.extend_from_slice(&u32b(ifd));
            out.extend_from_slice(data);
            out.resize(ifd as usize, 0);
            out.extend_from_slice(&u16b(entries.len() as u16));
            let mut extra = Vec::new();
            for (tag, typ, count, bytes) in &entries {
                out.extend_from_slice(&u16b(*tag));
                out.extend_from_slice(&u16b(*typ));
                out.extend_from_slice(&u32b(*count));
                if bytes.len() <= 4 {
                    let mut field = bytes.clone();
                    field.resize(4, 0);
                    out.extend_from_slice(&field);
                } else {
                    out.extend_from_slice(&u32b(extra_at));
                    extra.extend_from_slice(bytes);
                    if bytes.len() % 2 == 1 {
                        extra.push(0);
                    }
                    extra_at = ifd + 2 + 12 * entries.len() as u32 + 4 + extra.len() as u32;
                }
            }
            out.extend_from_slice(&u32b(0));
            out.extend_from_slice(&extra);
            out
        }
    }

    fn i16_bytes(le: bool, v: &[i16]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| if le { x.to_le_bytes() } else { x.to_be_bytes() })
            .collect()
    }

    fn small_georef(epsg: Option<u32>) -> Georef {
        Georef {
            origin: [500000.0, 4649776.5],
            pixel_size: [30.0, 30.0],
            raster_type: RasterType::Area,
            epsg,
            wkt: None,
            geokeys: None,
        }
    }

    /// A small int16 raster with a georef, nodata and a few invalid samples.
    fn small_i16_raster() -> Raster {
        let (w, h) = (23, 17);
        let mut data: Vec<f64> = (0..w * h)
            .map(|i| ((i * 37) % 1000) as f64 - 200.0)
            .collect();
        data[5] = -9999.0;
        data[100] = -9999.0;
        let mut r = Raster::from_values(w, h, data, Some(-9999.0), SampleType::I16).unwrap();
        r.georef = Some(small_georef(Some(32611)));
        r
    }

    fn is_unsupported(e: &Error) -> bool {
        matches!(e, Error::Unsupported { .. })
    }

    // ----- corpus -----------------------------------------------------------------------

    #[test]
    fn corpus_tifs_match_reference_f32() {
        let Some(dir) = corpus() else { return };
        for name in CORPUS_TIFS {
            let tif = std::fs::read(dir.join(format!("{name}.tif"))).unwrap();
            let reference = std::fs::read(dir.join(format!("{name}.f32"))).unwrap();
            let json: serde_json::Value =
                serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap())
                    .unwrap();
            let r = read(&tif, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(r.width as u64, json["width"].as_u64().unwrap(), "{name}");
            assert_eq!(r.height as u64, json["height"].as_u64().unwrap(), "{name}");
            // serde_json (without its float_roundtrip feature) may misread the last bit of
            // a double, so the nodata is compared as the f32 the samples hold.
            let json_nodata = json["nodata"].as_f64();
            assert_eq!(
                r.nodata.map(|v| (v as f32).to_bits()),
                json_nodata.map(|v| (v as f32).to_bits()),
                "{name}: nodata"
            );
            let g = r.georef.as_ref().expect("georeferenced");
            assert_eq!(
                g.pixel_size,
                [json["dx"].as_f64().unwrap(), json["dy"].as_f64().unwrap()],
                "{name}: pixel size"
            );
            assert!(g.geokeys.is_some(), "{name}: geokeys kept");
            assert_eq!(reference.len(), r.len() * 4, "{name}: reference length");
            let mut invalid = 0;
            for (i, chunk) in reference.chunks_exact(4).enumerate() {
                let want = u32::from_le_bytes(chunk.try_into().unwrap());
                let got = if r.is_valid(i) {
                    r.data[i] as f32
                } else {
                    invalid += 1;
                    json_nodata.expect("invalid samples need a nodata") as f32
                };
                assert_eq!(
                    got.to_bits(),
                    want,
                    "{name}: sample {i} is {got}, reference {}",
                    f32::from_bits(want)
                );
            }
            let frac = json["stats"]["nodata_fraction"].as_f64().unwrap();
            assert!(
                (invalid as f64 / r.len() as f64 - frac).abs() < 1e-5,
                "{name}: nodata fraction"
            );
        }
    }

    #[test]
    fn corpus_specifics() {
        let Some(dir) = corpus() else { return };
        let read_name = |n: &str| {
            read(
                &std::fs::read(dir.join(format!("{n}.tif"))).unwrap(),
                &opts(),
            )
            .unwrap()
        };
        let texas = read_name("pysheds_dem_texas");
        assert_eq!(texas.sample_type, SampleType::I16);
        assert_eq!(texas.nodata, Some(-32768.0));
        assert_eq!(texas.mask, None);
        let texas_g = texas.georef.unwrap();
        assert_eq!(texas_g.epsg, Some(4326));
        assert_eq!(texas_g.origin, [-97.4849999999961, 32.82166666666536]);

        let tujunga = read_name("srtm30m_bigtujunga_utm11");
        assert_eq!(
            tujunga.nodata,
            Some(32767.0),
            "declared nodata kept though unused"
        );
        assert_eq!(tujunga.mask, None);
        let g = tujunga.georef.unwrap();
        assert_eq!(g.epsg, Some(32611));
        assert_eq!(g.raster_type, RasterType::Area);
        assert_eq!(g.origin, [376313.6554542635, 3807917.8276283755]);

        let lux = read_name("terra_elev_luxembourg");
        assert!(lux.mask.is_some());

        let vin = read_name("terra_elev_vinschgau");
        assert_eq!(vin.sample_type, SampleType::F32);
        assert_eq!(vin.nodata, Some(-3.3999999521443642e38));
        assert_eq!(vin.georef.unwrap().origin, [598250.0, 5193000.0]);
    }

    #[test]
    fn corpus_round_trip_is_identical() {
        let Some(dir) = corpus() else { return };
        for name in CORPUS_TIFS {
            let tif = std::fs::read(dir.join(format!("{name}.tif"))).unwrap();
            let a = read(&tif, &opts()).unwrap();
            let bytes = write(&a).unwrap_or_else(|e| panic!("{name}: {e}"));
            let b = read(&bytes, &opts()).unwrap();
            assert_same(&a, &b, name);
            // And once more: the writer is stable.
            assert_eq!(write(&b).unwrap(), bytes, "{name}: second write");
        }
    }

    fn raw_tag(bytes: &[u8], tag: Tag) -> Option<Value> {
        let mut d = Decoder::new(Cursor::new(bytes)).unwrap();
        d.find_tag(tag).unwrap()
    }

    #[test]
    fn corpus_written_tags_read_back_raw() {
        let Some(dir) = corpus() else { return };
        for name in CORPUS_TIFS {
            let src = std::fs::read(dir.join(format!("{name}.tif"))).unwrap();
            let r = read(&src, &opts()).unwrap();
            let out = write(&r).unwrap();
            let g = r.georef.as_ref().unwrap();

            let f64s = |b: &[u8], t: Tag| raw_tag(b, t).unwrap().into_f64_vec().unwrap();
            let src_scale = f64s(&src, Tag::ModelPixelScaleTag);
            let out_scale = f64s(&out, Tag::ModelPixelScaleTag);
            assert_eq!(out_scale, vec![src_scale[0], src_scale[1], 0.0], "{name}");
            let src_tie = f64s(&src, Tag::ModelTiepointTag);
            let out_tie = f64s(&out, Tag::ModelTiepointTag);
            assert_eq!(
                out_tie,
                vec![
                    0.0,
                    0.0,
                    0.0,
                    src_tie[3] - src_tie[0] * src_scale[0],
                    src_tie[4] + src_tie[1] * src_scale[1],
                    0.0
                ],
                "{name}"
            );
            assert_eq!(out_tie[3..5], g.origin, "{name}");

            let shorts = |b: &[u8], t: Tag| raw_tag(b, t).map(|v| v.into_u16_vec().unwrap());
            assert_eq!(
                shorts(&out, Tag::GeoKeyDirectoryTag),
                shorts(&src, Tag::GeoKeyDirectoryTag),
                "{name}: GeoKeyDirectory"
            );
            let doubles =
                |b: &[u8]| raw_tag(b, Tag::GeoDoubleParamsTag).map(|v| v.into_f64_vec().unwrap());
            assert_eq!(doubles(&out), doubles(&src), "{name}: GeoDoubleParams");
            let ascii =
                |b: &[u8]| raw_tag(b, Tag::GeoAsciiParamsTag).map(|v| v.into_string().unwrap());
            assert_eq!(ascii(&out), ascii(&src), "{name}: GeoAsciiParams");

            let nodata = raw_tag(&out, Tag::GdalNodata)
                .unwrap()
                .into_string()
                .unwrap();
            let parsed: f64 = nodata.trim().parse().unwrap();
            assert_eq!(Some(parsed), r.nodata, "{name}: GDAL_NODATA '{nodata}'");

            // Layout: Deflate, predictor 2 for integers, none for floats.
            let mut d = Decoder::new(Cursor::new(&out[..])).unwrap();
            assert_eq!(d.get_tag_u32(Tag::Compression).unwrap(), 8);
            let pred = d.get_tag_u32(Tag::Predictor).unwrap();
            assert_eq!(
                pred,
                if r.sample_type.is_integer() { 2 } else { 1 },
                "{name}"
            );
        }
    }

    // ----- synthetic round trips ----------------------------------------------------------

    #[test]
    fn nan_holes_without_georef_round_trip() {
        for st in [SampleType::F32, SampleType::F64] {
            let (w, h) = (31, 9);
            let data: Vec<f64> = (0..w * h)
                .map(|i| {
                    if i % 7 == 3 {
                        f64::NAN
                    } else {
                        i as f64 * 0.25 - 3.0
                    }
                })
                .collect();
            let r = Raster::from_values(w, h, data, None, st).unwrap();
            assert!(r.mask.is_some());
            let bytes = write(&r).unwrap();
            let back = read(&bytes, &opts()).unwrap();
            assert_same(&r, &back, st.name());
            assert_eq!(back.georef, None);
            // GDAL is told that NaN is nodata.
            let nd = raw_tag(&bytes, Tag::GdalNodata)
                .unwrap()
                .into_string()
                .unwrap();
            assert_eq!(nd, "nan");
        }
    }

    #[test]
    fn every_sample_type_round_trips() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let cases: [(SampleType, f64, f64, Option<f64>); 6] = [
            (SampleType::U8, 0.0, 255.0, Some(0.0)),
            (SampleType::I16, -32768.0, 32767.0, Some(-32768.0)),
            (SampleType::U16, 0.0, 65535.0, None),
            (SampleType::I32, -2147483648.0, 2147483647.0, Some(-9999.0)),
            (SampleType::F32, -1e6, 1e6, Some(-3.3999999521443642e38)),
            (SampleType::F64, -1e6, 1e6, Some(-1e300)),
        ];
        for (st, lo, hi, nodata) in cases {
            for (w, h) in [(1, 1), (3, 2), (257, 130), (1, 300), (4000, 3)] {
                let data: Vec<f64> = (0..w * h)
                    .map(|_| {
                        let hole = rng.below(10) == 0;
                        if let (Some(nd), true) = (nodata, hole) {
                            return nd;
                        }
                        let u = rng.next() as f64 / u64::MAX as f64;
                        let v = lo + (hi - lo) * u;
                        match st {
                            SampleType::F32 => f64::from(v as f32),
                            SampleType::F64 => v,
                            // + 0.0: an integer sample has no negative zero.
                            _ => v.round().clamp(lo, hi) + 0.0,
                        }
                    })
                    .collect();
                let mut r = Raster::from_values(w, h, data, nodata, st).unwrap();
                r.georef = Some(small_georef(Some(4326)));
                let back = read(&write(&r).unwrap(), &opts()).unwrap();
                assert_eq!(back.sample_type, st);
                assert_eq!(back.data.len(), r.data.len());
                // The synthesised GeoKeys are new, everything else is identical.
                let g = back.georef.clone().unwrap();
                assert_eq!(g.epsg, Some(4326));
                assert_eq!(
                    g.geokeys.as_ref().unwrap().directory,
                    vec![1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326]
                );
                let mut expect = r.clone();
                expect.georef.as_mut().unwrap().geokeys = g.geokeys.clone();
                assert_same(&expect, &back, &format!("{} {w}x{h}", st.name()));
            }
        }
    }

    #[test]
    fn integer_values_are_rounded_and_range_checked() {
        let r =
            Raster::from_values(4, 1, vec![1.4, 2.6, -3.5, 7.0], None, SampleType::I16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.data, vec![1.0, 3.0, -4.0, 7.0]);

        let r = Raster::from_values(3, 1, vec![1.0, 40000.0, 2.0], None, SampleType::I16).unwrap();
        let e = write(&r).unwrap_err();
        assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
        assert!(e.to_string().contains("40000"), "{e}");

        let r = Raster::from_values(2, 1, vec![-1.0, 2.0], None, SampleType::U8).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));

        // A nodata value that the type cannot hold is an error only when it must be written.
        let r =
            Raster::from_values(2, 1, vec![1.0, -9999.0], Some(-9999.0), SampleType::U16).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
        let r = Raster::from_values(2, 1, vec![1.0, 2.0], Some(-9999.0), SampleType::U16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "unused out-of-range nodata");
    }

    #[test]
    fn integer_holes_without_nodata_get_a_type_extreme() {
        let data = vec![1.0, f64::NAN, 3.0, -32768.0];
        let r = Raster::from_values(2, 2, data, None, SampleType::I16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        // -32768 is used by a valid sample, so the maximum is used instead.
        assert_eq!(back.nodata, Some(32767.0));
        assert_eq!(back.mask, r.mask);
        assert_eq!(back.data, vec![1.0, 32767.0, 3.0, -32768.0]);

        let r = Raster::from_values(2, 1, vec![5.0, f64::NAN], None, SampleType::U16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.nodata, Some(65535.0));
        assert_eq!(back.mask, Some(vec![true, false]));
    }

    #[test]
    fn mapped_integer_raster_is_written_as_float() {
        let mut r =
            Raster::from_values(3, 1, vec![0.5, 1.25, -7.0], None, SampleType::U16).unwrap();
        r.mapping = ValueMapping {
            scale: 0.25,
            offset: -10.0,
        };
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::F32);
        assert_eq!(back.data, r.data);
        r.data[0] = 0.1; // not exact in f32
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::F64);
        assert_eq!(back.data, r.data);
    }

    #[test]
    fn written_file_structure() {
        let r = small_i16_raster();
        let bytes = write(&r).unwrap();
        let mut d = Decoder::new(Cursor::new(&bytes[..])).unwrap();
        assert_eq!(d.dimensions().unwrap(), (23, 17));
        assert_eq!(d.get_tag_u32(Tag::SamplesPerPixel).unwrap(), 1);
        assert_eq!(d.get_tag_u32(Tag::BitsPerSample).unwrap(), 16);
        assert_eq!(d.get_tag_u32(Tag::SampleFormat).unwrap(), 2);
        assert_eq!(d.get_tag_u32(Tag::Compression).unwrap(), 8);
        assert_eq!(d.get_tag_u32(Tag::Predictor).unwrap(), 2);
        assert_eq!(
            d.get_tag_ascii_string(Tag::GdalNodata).unwrap(),
            "-9999".to_string()
        );
        assert_eq!(
            d.get_tag_u16_vec(Tag::GeoKeyDirectoryTag).unwrap(),
            vec![1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32611]
        );
        assert!(d.find_tag(Tag::GeoDoubleParamsTag).unwrap().is_none());
        assert!(d.find_tag(Tag::GeoAsciiParamsTag).unwrap().is_none());
        let back = read(&bytes, &opts()).unwrap();
        assert_eq!(back.georef.as_ref().unwrap().epsg, Some(32611));
        assert_eq!(back.data, r.data);
        assert_eq!(back.mask, r.mask);
    }

    #[test]
    fn raster_type_point_is_written_into_the_geokeys() {
        // Synthesised keys.
        let mut r = small_i16_raster();
        r.georef.as_mut().unwrap().raster_type = RasterType::Point;
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.georef.as_ref().unwrap().raster_type, RasterType::Point);

        // Verbatim keys without GTRasterTypeGeoKey: the key is inserted in order.
        let keys = GeoKeys {
            directory: vec![
                1, 1, 0, 3, 1024, 0, 1, 2, 2048, 0, 1, 4326, 2054, 34736, 1, 0,
            ],
            doubles: vec![0.0174532925199433],
            ascii: "WGS 84|".to_string(),
        };
        let mut g = r.georef.clone().unwrap();
        g.geokeys = Some(keys.clone());
        g.raster_type = RasterType::Area;
        r.georef = Some(g.clone());
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.georef.as_ref().unwrap().geokeys.as_ref(), Some(&keys));
        g.raster_type = RasterType::Point;
        r.georef = Some(g);
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        let bg = back.georef.unwrap();
        assert_eq!(bg.raster_type, RasterType::Point);
        assert_eq!(bg.epsg, Some(4326));
        let k = bg.geokeys.unwrap();
        assert_eq!(
            k.directory,
            vec![
                1, 1, 0, 4, 1024, 0, 1, 2, 1025, 0, 1, 2, 2048, 0, 1, 4326, 2054, 34736, 1, 0
            ]
        );
        assert_eq!(k.doubles, keys.doubles);
        assert_eq!(k.ascii, keys.ascii);

        // And an existing key is overwritten.
        let mut dir = k.directory.clone();
        set_raster_type_key(&mut dir, RASTER_PIXEL_IS_AREA).unwrap();
        assert_eq!(dir[8..12], [1025, 0, 1, 1]);
    }

    #[test]
    fn non_ascii_geoascii_params_survive() {
        let mut r = small_i16_raster();
        let g = r.georef.as_mut().unwrap();
        g.geokeys = Some(GeoKeys {
            directory: vec![1, 1, 0, 2, 1024, 0, 1, 1, 1026, 34737, 26, 0],
            doubles: vec![],
            ascii: "Réseau géodésique français|".to_string(),
        });
        g.epsg = None;
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "non-ASCII citation");
    }

    #[test]
    fn geokeys_without_placement_are_kept() {
        let vals: Vec<i16> = (0..6).collect();
        let mut b = Builder::basic(true, 3, 2, 16, 2, 12);
        b.short(TAG_GEO_KEY_DIRECTORY, &[1, 1, 0, 1, 3072, 0, 1, 32633]);
        let r = read(&b.build(&i16_bytes(true, &vals)), &opts()).unwrap();
        let g = r.georef.clone().unwrap();
        assert_eq!((g.origin, g.pixel_size), ([0.0, 0.0], [1.0, 1.0]));
        assert_eq!(g.epsg, Some(33633 - 1000));
        assert_eq!(g.geokeys.as_ref().unwrap().directory[7], 32633);
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "geokeys only");

        // No georeferencing tags at all: no georef.
        let b = Builder::basic(true, 3, 2, 16, 2, 12);
        let r = read(&b.build(&i16_bytes(true, &vals)), &opts()).unwrap();
        assert_eq!(r.georef, None);
        assert_eq!(r.nodata, None);
        assert_eq!(r.data, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    }

    #[test]
    fn epsg_rules() {
        let dir = |keys: &[[u16; 4]]| {
            let mut d = vec![1, 1, 0, keys.len() as u16];
            d.extend(keys.iter().flatten());
            d
        };
        let epsg_of = |d: Vec<u16>| {
            let mut b = Builder::basic(true, 1, 1, 16, 2, 2);
            b.short(TAG_GEO_KEY_DIRECTORY, &d);
            read(&b.build(&[0, 0]), &opts())
                .unwrap()
                .georef
                .unwrap()
                .epsg
        };
        assert_eq!(
            epsg_of(dir(&[[1024, 0, 1, 2], [2048, 0, 1, 4326]])),
            Some(4326)
        );
        assert_eq!(epsg_of(dir(&[[2048, 0, 1, 4269]])), Some(4269));
        assert_eq!(epsg_of(dir(&[[2048, 0, 1, 32767]])), None);
        assert_eq!(epsg_of(dir(&[[2048, 0, 1, 0]])), None);
        assert_eq!(
            epsg_of(dir(&[
                [1024, 0, 1, 1],
                [2048, 0, 1, 4326],
                [3072, 0, 1, 32767]
            ])),
            None,
            "user-defined projection on a known datum is not the datum's code"
        );
        assert_eq!(epsg_of(dir(&[[1024, 0, 1, 1], [2048, 0, 1, 4326]])), None);
        assert_eq!(
            epsg_of(dir(&[
                [1024, 0, 1, 1],
                [2048, 0, 1, 4326],
                [3072, 0, 1, 32633]
            ])),
            Some(32633)
        );
        // A directory that claims more keys than it holds is read without panicking.
        assert_eq!(epsg_of(vec![1, 1, 0, 9, 3072, 0, 1, 2056]), Some(2056));
        assert_eq!(epsg_of(vec![1, 1, 0, 9, 3072, 0]), None);
    }

    #[test]
    fn model_transformation() {
        let mut b = Builder::basic(true, 2, 1, 16, 2, 4);
        let m = [
            10.0, 0.0, 0.0, 1000.0, 0.0, -20.0, 0.0, 5000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ];
        b.double(TAG_MODEL_TRANSFORMATION, &m);
        let r = read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap();
        let g = r.georef.unwrap();
        assert_eq!(g.origin, [1000.0, 5000.0]);
        assert_eq!(g.pixel_size, [10.0, 20.0]);
        assert_eq!(g.geokeys, None);

        let mut rotated = m;
        rotated[1] = 0.5;
        b.double(TAG_MODEL_TRANSFORMATION, &rotated);
        let e = read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap_err();
        assert!(is_unsupported(&e), "{e}");

        // Ground control points only.
        let mut b = Builder::basic(true, 2, 1, 16, 2, 4);
        b.double(TAG_MODEL_TIEPOINT, &[0.0; 12]);
        let e = read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap_err();
        assert!(is_unsupported(&e), "{e}");
    }

    #[test]
    fn tiepoint_not_at_origin() {
        let mut b = Builder::basic(false, 2, 2, 16, 2, 8);
        b.double(TAG_MODEL_PIXEL_SCALE, &[2.0, 3.0, 0.0]);
        b.double(TAG_MODEL_TIEPOINT, &[1.0, 1.0, 0.0, 102.0, 197.0, 0.0]);
        let r = read(&b.build(&i16_bytes(false, &[1, -2, 300, -32768])), &opts()).unwrap();
        assert_eq!(
            r.data,
            vec![1.0, -2.0, 300.0, -32768.0],
            "big-endian samples"
        );
        let g = r.georef.unwrap();
        assert_eq!(g.origin, [100.0, 200.0]);
        assert_eq!(g.pixel_size, [2.0, 3.0]);
    }

    #[test]
    fn float32_nodata_is_rounded_to_float32() {
        let nd32 = -3.4e38f32;
        let vals = [1.5f32, nd32, f32::NAN, 2.0];
        let data: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut b = Builder::basic(true, 2, 2, 32, 3, 16);
        b.ascii(TAG_GDAL_NODATA, "-3.39999999999999996e+38\0\0 ");
        let r = read(&b.build(&data), &opts()).unwrap();
        assert_eq!(r.nodata, Some(-3.3999999521443642e38));
        assert_eq!(r.mask, Some(vec![true, false, false, true]));
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "f32 nodata");

        // A NaN nodata is no nodata (NaN samples are invalid anyway).
        b.ascii(TAG_GDAL_NODATA, "nan");
        let r = read(&b.build(&data), &opts()).unwrap();
        assert_eq!(r.nodata, None);
        assert_eq!(r.mask, Some(vec![true, true, false, true]));

        b.ascii(TAG_GDAL_NODATA, " ");
        assert_eq!(read(&b.build(&data), &opts()).unwrap().nodata, None);

        b.ascii(TAG_GDAL_NODATA, "none");
        assert!(matches!(
            read(&b.build(&data), &opts()),
            Err(Error::Corrupt { .. })
        ));
    }

    #[test]
    fn nodata_text_round_trips() {
        for v in [
            -9999.0,
            0.0,
            -32768.0,
            0.1,
            -3.3999999521443642e38,
            f64::from(f32::MAX),
            1e300,
            -1e-300,
            123456789012345678.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            let s = format_nodata(v);
            assert_eq!(parse_nodata(&s), Some(v), "{v} -> {s}");
        }
        assert!(parse_nodata(&format_nodata(f64::NAN)).unwrap().is_nan());
        assert_eq!(format_nodata(-9999.0), "-9999");
        assert_eq!(parse_nodata(" -32768\0"), Some(-32768.0));
    }

    /// Forward TIFF floating-point predictor (3) on one row of float32 samples.
    fn fp_predict_row(row: &[f32]) -> Vec<u8> {
        let n = row.len();
        let mut s = vec![0u8; n * 4];
        for (i, v) in row.iter().enumerate() {
            for (k, byte) in v.to_be_bytes().into_iter().enumerate() {
                s[k * n + i] = byte;
            }
        }
        for i in (1..s.len()).rev() {
            s[i] = s[i].wrapping_sub(s[i - 1]);
        }
        s
    }

    #[test]
    fn float_predictor_3_is_read() {
        let (w, h) = (5usize, 3usize);
        let vals: Vec<f32> = (0..w * h).map(|i| 1000.0 + i as f32 * 0.37).collect();
        let data: Vec<u8> = vals.chunks(w).flat_map(fp_predict_row).collect();
        let mut b = Builder::basic(true, w as u32, h as u32, 32, 3, data.len());
        b.short(TAG_PREDICTOR, &[3]);
        let r = read(&b.build(&data), &opts()).unwrap();
        let want: Vec<f64> = vals.iter().map(|&v| f64::from(v)).collect();
        assert_eq!(r.data, want);
    }

    #[test]
    fn tiled_multi_strip_and_other_encoders() {
        // Written by the tiff crate with LZW and several strips, int32 and uint8.
        let (w, h) = (40u32, 33u32);
        let vals: Vec<i32> = (0..w * h).map(|i| (i as i32 - 600) * 1000).collect();
        let mut out = Cursor::new(Vec::new());
        {
            let mut enc = TiffEncoder::new(&mut out)
                .unwrap()
                .with_compression(Compression::Lzw)
                .with_predictor(Predictor::Horizontal);
            let mut img = enc.new_image::<GrayI32>(w, h).unwrap();
            img.rows_per_strip(4).unwrap();
            img.write_data(&vals).unwrap();
        }
        let r = read(out.get_ref(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::I32);
        assert_eq!(
            r.data,
            vals.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()
        );

        // Hand-made tiles (2x2 tiles of 4x4 over a 6x5 image, uncompressed).
        let (w, h, t) = (6usize, 5usize, 4usize);
        let value = |x: usize, y: usize| (y * 10 + x) as i16;
        let mut data = Vec::new();
        let mut offsets = Vec::new();
        for ty in 0..2 {
            for tx in 0..2 {
                offsets.push(8 + data.len() as u32);
                for y in 0..t {
                    for x in 0..t {
                        let (gx, gy) = (tx * t + x, ty * t + y);
                        let v = if gx < w && gy < h { value(gx, gy) } else { 0 };
                        data.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
        }
        let mut b = Builder::basic(true, w as u32, h as u32, 16, 2, 0);
        b.remove(TAG_STRIP_OFFSETS)
            .remove(TAG_STRIP_BYTE_COUNTS)
            .remove(TAG_ROWS_PER_STRIP)
            .long(TAG_TILE_WIDTH, &[t as u32])
            .long(TAG_TILE_LENGTH, &[t as u32])
            .long(TAG_TILE_OFFSETS, &offsets)
            .long(TAG_TILE_BYTE_COUNTS, &[32; 4]);
        let r = read(&b.build(&data), &opts()).unwrap();
        let want: Vec<f64> = (0..w * h).map(|i| f64::from(value(i % w, i / w))).collect();
        assert_eq!(r.data, want);
    }

    // ----- unsupported and broken input ---------------------------------------------------

    #[test]
    fn rgb_is_unsupported() {
        let mut out = Cursor::new(Vec::new());
        TiffEncoder::new(&mut out)
            .unwrap()
            .write_image::<tiff::encoder::colortype::RGB8>(4, 3, &[7u8; 36])
            .unwrap();
        let e = read(out.get_ref(), &opts()).unwrap_err();
        assert!(is_unsupported(&e), "{e}");
        let msg = e.to_string();
        assert!(msg.contains("3 samples per pixel"), "{msg}");
    }

    #[test]
    fn unsupported_layouts() {
        type Change = Box<dyn Fn(&mut Builder)>;
        let cases: Vec<(&str, Change, &str)> = vec![
            (
                "12-bit",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_BITS_PER_SAMPLE, &[12]);
                }),
                "12 bits per sample",
            ),
            (
                "1-bit",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_BITS_PER_SAMPLE, &[1]);
                }),
                "1 bits per sample",
            ),
            (
                "palette",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_PHOTOMETRIC, &[3]);
                }),
                "palette",
            ),
            (
                "int8",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_BITS_PER_SAMPLE, &[8]);
                }),
                "int8",
            ),
            (
                "uint32",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_BITS_PER_SAMPLE, &[32])
                        .short(TAG_SAMPLE_FORMAT, &[1]);
                }),
                "uint32",
            ),
            (
                "jpeg",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_COMPRESSION, &[7]);
                }),
                "JPEG",
            ),
            (
                "zstd",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_COMPRESSION, &[50000]);
                }),
                "Zstandard",
            ),
            (
                "planar 2 bands",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_SAMPLES_PER_PIXEL, &[2])
                        .short(TAG_PLANAR_CONFIG, &[2])
                        .short(TAG_BITS_PER_SAMPLE, &[16, 16])
                        .short(TAG_SAMPLE_FORMAT, &[2, 2]);
                }),
                "2 samples per pixel",
            ),
            (
                "fp predictor on ints",
                Box::new(|b: &mut Builder| {
                    b.short(TAG_PREDICTOR, &[3]);
                }),
                "predictor",
            ),
        ];
        for (name, change, needle) in cases {
            let mut b = Builder::basic(true, 2, 2, 16, 2, 8);
            change(&mut b);
            let e = read(&b.build(&[0; 8]), &opts()).unwrap_err();
            assert!(is_unsupported(&e), "{name}: {e}");
            assert!(e.to_string().contains(needle), "{name}: {e}");
            assert!(!e.to_string().contains('\n'), "{name}: one line");
        }
        // Planar configuration 2 with one band is just a single band.
        let mut b = Builder::basic(true, 2, 1, 16, 2, 4);
        b.short(TAG_PLANAR_CONFIG, &[2]);
        assert_eq!(
            read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap().data,
            vec![1.0, 2.0]
        );
    }

    #[test]
    fn huge_header_is_a_limit_error() {
        let mut b = Builder::basic(true, 100_000, 100_000, 16, 2, 8);
        b.long(TAG_ROWS_PER_STRIP, &[100_000]);
        let e = read(&b.build(&[0; 8]), &opts()).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");

        // A huge tile is refused too.
        let mut b = Builder::basic(true, 4, 4, 16, 2, 0);
        b.remove(TAG_STRIP_OFFSETS)
            .remove(TAG_STRIP_BYTE_COUNTS)
            .long(TAG_TILE_WIDTH, &[1 << 30])
            .long(TAG_TILE_LENGTH, &[1 << 30])
            .long(TAG_TILE_OFFSETS, &[8])
            .long(TAG_TILE_BYTE_COUNTS, &[8]);
        let e = read(&b.build(&[0; 8]), &opts()).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");

        // The caller's limit applies.
        let bytes = write(&small_i16_raster()).unwrap();
        let small = ReadOptions {
            max_samples: Some(100),
            ..ReadOptions::default()
        };
        let e = read(&bytes, &small).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
        assert!(read(&bytes, &opts()).is_ok());
    }

    #[test]
    fn garbage_bytes_are_errors() {
        let mut rng = Rng(12345);
        for len in [0usize, 1, 2, 3, 4, 7, 8, 9, 16, 100, 1000, 5000] {
            for prefix in [&b""[..], b"II*\0", b"MM\0*", b"II+\0\x08\0\0\0"] {
                for _ in 0..20 {
                    let mut b = prefix.to_vec();
                    b.extend((0..len).map(|_| rng.next() as u8));
                    assert!(read(&b, &opts()).is_err());
                }
            }
        }
    }

    #[test]
    fn truncations_are_errors() {
        let written = write(&small_i16_raster()).unwrap();
        let vals: Vec<i16> = (0..12).collect();
        let mut b = Builder::basic(true, 4, 3, 16, 2, 24);
        b.double(TAG_MODEL_PIXEL_SCALE, &[1.0, 1.0, 0.0])
            .double(TAG_MODEL_TIEPOINT, &[0.0, 0.0, 0.0, 5.0, 6.0, 0.0])
            .ascii(TAG_GDAL_NODATA, "-1");
        let handmade = b.build(&i16_bytes(true, &vals));
        assert!(read(&handmade, &opts()).is_ok());
        for file in [&written, &handmade] {
            for len in 0..file.len() {
                let r = read(&file[..len], &opts());
                assert!(r.is_err(), "truncated to {len} of {} bytes", file.len());
            }
        }
        let Some(dir) = corpus() else { return };
        let tif = std::fs::read(dir.join("terra_elev_luxembourg.tif")).unwrap();
        for k in 0..50 {
            let len = tif.len() * k / 50;
            assert!(read(&tif[..len], &opts()).is_err(), "truncated to {len}");
        }
    }

    #[test]
    fn mutated_files_never_panic() {
        let mut inputs = vec![write(&small_i16_raster()).unwrap()];
        let mut f = small_i16_raster();
        f.sample_type = SampleType::F32;
        inputs.push(write(&f).unwrap());
        let vals: Vec<f32> = (0..15).map(|i| i as f32).collect();
        let data: Vec<u8> = vals.chunks(5).flat_map(fp_predict_row).collect();
        let mut b = Builder::basic(true, 5, 3, 32, 3, data.len());
        b.short(TAG_PREDICTOR, &[3])
            .double(TAG_MODEL_PIXEL_SCALE, &[1.0, 1.0, 0.0])
            .double(TAG_MODEL_TIEPOINT, &[0.0, 0.0, 0.0, 5.0, 6.0, 0.0])
            .short(TAG_GEO_KEY_DIRECTORY, &[1, 1, 0, 1, 1025, 0, 1, 2]);
        inputs.push(b.build(&data));
        if let Some(dir) = corpus() {
            inputs.push(std::fs::read(dir.join("terra_elev_luxembourg.tif")).unwrap());
        }
        // VTZ_FUZZ_ITERS raises the number of mutations per input for a longer run.
        let iters: usize = std::env::var("VTZ_FUZZ_ITERS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(600);
        let mut rng = Rng(0xdead_beef);
        for input in &inputs {
            for _ in 0..iters {
                let mut m = input.clone();
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(m.len() as u64) as usize;
                    m[i] = match rng.below(4) {
                        0 => 0,
                        1 => 0xff,
                        _ => rng.next() as u8,
                    };
                }
                // Any result is fine; it must not panic or allocate wildly.
                let _ = read(&m, &opts());
            }
        }
    }
}
