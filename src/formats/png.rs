//! 16-bit (and 8-bit) greyscale PNG height maps with a value mapping, and Mapbox Terrain-RGB PNGs.
//!
//! Grey PNGs hold integer codes; `value = offset + scale · code`, and an optional
//! `nodata_code` marks voids (as does alpha 0 in grey+alpha PNGs). The mapping, and the
//! georeferencing, travel in a `NAME.png.json` sidecar:
//! `{"scale": s, "offset": o, "nodata_code": c|null, "georef": {...}|null}` (the georef
//! object is the shared one of [`crate::formats::sidecar`]).
//!
//! 8-bit RGB/RGBA PNGs hold heights in one of two encodings of web-map terrain tiles (alpha 0
//! marks voids), said by `--format` or vtz's sidecar:
//! - Mapbox Terrain-RGB: `height = -10000 + (R·65536 + G·256 + B) · 0.1`, computed in f64
//!   and rounded to f32;
//! - Terrarium (Mapzen/AWS terrain tiles): `height = (R·256 + G + B/256) - 32768`, exact in
//!   f32 (steps of 1/256).

use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::formats::samples::Rounding;
use crate::formats::sidecar::{ExactF64, GeorefJson, expect_json_object};
use crate::model::{Georef, Raster, SampleType, ValueMapping, check_size};
use image::codecs::png::{CompressionType, FilterType, PngDecoder, PngEncoder};
use image::{ColorType, ExtendedColorType, ImageDecoder, ImageEncoder, ImageError};
use serde::{Deserialize, Serialize};
use std::io::Cursor;
use std::path::{Path, PathBuf};

/// Value mapping of a 16-bit PNG: value = offset + scale * code; `nodata_code` marks voids.
#[derive(Clone, Debug, PartialEq)]
pub struct PngMapping {
    /// Value per code step.
    pub scale: f64,
    /// Value of code 0.
    pub offset: f64,
    /// The code that marks nodata, if any.
    pub nodata_code: Option<u16>,
}

impl PngMapping {
    fn value_mapping(&self) -> ValueMapping {
        ValueMapping {
            scale: self.scale,
            offset: self.offset,
        }
    }
}

/// What a `NAME.png.json` sidecar holds.
#[derive(Clone, Debug, PartialEq)]
pub struct PngSidecar {
    pub mapping: PngMapping,
    pub georef: Option<Georef>,
}

fn one() -> ExactF64 {
    ExactF64(1.0)
}
fn zero() -> ExactF64 {
    ExactF64(0.0)
}

#[derive(Serialize, Deserialize)]
struct SidecarJson {
    #[serde(default = "one")]
    scale: ExactF64,
    #[serde(default = "zero")]
    offset: ExactF64,
    #[serde(default)]
    nodata_code: Option<u16>,
    #[serde(default)]
    georef: Option<GeorefJson>,
}

/// Terrain-RGB mapping: height = -10000 + 0.1 · code.
pub const TERRAIN_RGB: ValueMapping = ValueMapping {
    scale: 0.1,
    offset: -10000.0,
};
const TRGB_MAX_CODE: u32 = 0xFF_FFFF;

/// Height of a Terrain-RGB code, as the corpus decodes it: f64 arithmetic, rounded to f32.
fn trgb_value(code: u32) -> f64 {
    (-10000.0 + code as f64 * 0.1) as f32 as f64
}

/// Terrarium mapping of the 24-bit code `R·65536 + G·256 + B`: height = code / 256 - 32768.
pub const TERRARIUM: ValueMapping = ValueMapping {
    scale: 1.0 / 256.0,
    offset: -32768.0,
};

/// How an 8-bit RGB(A) PNG holds heights in its 24-bit code `R·65536 + G·256 + B`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RgbHeights {
    /// Mapbox Terrain-RGB: `-10000 + 0.1 · code`.
    TerrainRgb,
    /// Terrarium: `code / 256 - 32768` (`(R·256 + G + B/256) - 32768`).
    Terrarium,
}

impl RgbHeights {
    /// The value mapping of the codes.
    pub fn mapping(self) -> ValueMapping {
        match self {
            RgbHeights::TerrainRgb => TERRAIN_RGB,
            RgbHeights::Terrarium => TERRARIUM,
        }
    }
    /// The encoding a mapping names, if any.
    pub fn of_mapping(m: &ValueMapping) -> Option<RgbHeights> {
        [RgbHeights::TerrainRgb, RgbHeights::Terrarium]
            .into_iter()
            .find(|k| k.mapping() == *m)
    }
    /// The height of a code, as f32 (exact for Terrarium).
    fn value(self, code: u32) -> f64 {
        match self {
            RgbHeights::TerrainRgb => trgb_value(code),
            RgbHeights::Terrarium => (code as f64 / 256.0 - 32768.0) as f32 as f64,
        }
    }
    /// Its name for people.
    pub fn name(self) -> &'static str {
        match self {
            RgbHeights::TerrainRgb => "Terrain-RGB",
            RgbHeights::Terrarium => "Terrarium",
        }
    }
}

/// `path` + `.json`: where a PNG's mapping sidecar lives.
pub fn sidecar_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".json");
    PathBuf::from(s)
}

fn check_mapping(scale: f64, offset: f64) -> Result<()> {
    if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
        return Err(Error::invalid(format!(
            "PNG value mapping scale {scale}, offset {offset} is not usable (need a finite non-zero scale and a finite offset)"
        )));
    }
    let m = ValueMapping { scale, offset };
    if !(m.to_value(0.0).is_finite() && m.to_value(65535.0).is_finite()) {
        return Err(Error::invalid(format!(
            "PNG value mapping scale {scale}, offset {offset} gives non-finite values"
        )));
    }
    Ok(())
}

/// Parse a sidecar's bytes (`what` names it in errors).
pub fn parse_sidecar(bytes: &[u8], what: &str) -> Result<PngSidecar> {
    expect_json_object(bytes, &format!("PNG sidecar {what}"))?;
    let j: SidecarJson = serde_json::from_slice(bytes)
        .map_err(|e| Error::corrupt(format!("PNG sidecar {what}: {e}")))?;
    check_mapping(j.scale.0, j.offset.0).map_err(|e| match e {
        Error::InvalidArgument { what: w } => Error::corrupt(format!("PNG sidecar {what}: {w}")),
        other => other,
    })?;
    Ok(PngSidecar {
        mapping: PngMapping {
            scale: j.scale.0,
            offset: j.offset.0,
            nodata_code: j.nodata_code,
        },
        georef: j.georef.map(Georef::from),
    })
}

/// Read the sidecar of the PNG at `path` (see [`sidecar_path`]), `None` when there is none.
pub fn read_sidecar(path: &Path) -> Result<Option<PngSidecar>> {
    let sp = sidecar_path(path);
    match std::fs::read(&sp) {
        Ok(b) => parse_sidecar(&b, &sp.display().to_string()).map(Some),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(format!("PNG sidecar {}", sp.display()), e)),
    }
}

fn sidecar_bytes(m: &PngMapping, georef: Option<&Georef>) -> Result<Vec<u8>> {
    let j = SidecarJson {
        scale: ExactF64(m.scale),
        offset: ExactF64(m.offset),
        nodata_code: m.nodata_code,
        georef: georef.map(GeorefJson::from),
    };
    let mut v = serde_json::to_vec_pretty(&j)
        .map_err(|e| Error::invalid(format!("cannot encode PNG sidecar json: {e}")))?;
    v.push(b'\n');
    Ok(v)
}

fn image_error(e: ImageError) -> Error {
    match e {
        ImageError::Limits(l) => Error::limit(format!("PNG: {l}")),
        ImageError::Unsupported(u) => Error::unsupported(format!("PNG: {u}")),
        other => Error::corrupt(format!("PNG: {other}")),
    }
}

/// The PNG header fields vtz needs, read before any decoding.
struct Ihdr {
    width: u32,
    height: u32,
    bit_depth: u8,
    colour_type: u8,
}

fn read_ihdr(b: &[u8]) -> Result<Ihdr> {
    const SIG: [u8; 8] = [137, 80, 78, 71, 13, 10, 26, 10];
    if b.len() < 8 || b[..8] != SIG {
        return Err(Error::corrupt("not a PNG file (bad signature)"));
    }
    if b.len() < 33 {
        return Err(Error::corrupt("PNG is truncated inside its header"));
    }
    if b[8..16] != [0, 0, 0, 13, b'I', b'H', b'D', b'R'] {
        return Err(Error::corrupt(
            "PNG does not start with a 13-byte IHDR chunk",
        ));
    }
    let be = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    Ok(Ihdr {
        width: be(16),
        height: be(20),
        bit_depth: b[24],
        colour_type: b[25],
    })
}

fn describe(colour_type: u8, bit_depth: u8) -> String {
    let kind = match colour_type {
        0 => "greyscale",
        2 => "RGB",
        3 => "palette (indexed-colour)",
        4 => "greyscale+alpha",
        6 => "RGBA",
        _ => return format!("colour type {colour_type} (invalid)"),
    };
    format!("{bit_depth}-bit {kind}")
}

fn mark_invalid(mask: &mut Option<Vec<bool>>, n: usize, i: usize) {
    mask.get_or_insert_with(|| vec![true; n])[i] = false;
}

/// Read a PNG height map. `mapping` applies to grey PNGs (identity when `None`); an RGB/RGBA
/// PNG is read as heights only in the encoding `rgb` insists on, or that `mapping` names (vtz's
/// sidecar of a Terrain-RGB or Terrarium PNG).
pub fn read(
    bytes: &[u8],
    mapping: Option<&PngMapping>,
    rgb: Option<RgbHeights>,
    opts: &ReadOptions,
) -> Result<Raster> {
    let h = read_ihdr(bytes)?;
    let desc = describe(h.colour_type, h.bit_depth);
    let is_rgb = match (h.colour_type, h.bit_depth) {
        (0 | 4, 8 | 16) => false,
        (2 | 6, 8) => true,
        (0 | 2 | 3 | 4 | 6, _) => {
            return Err(Error::unsupported(format!(
                "{desc} PNG (vtz reads 8/16-bit greyscale, with or without alpha, and 8-bit RGB/RGBA Terrain-RGB)"
            )));
        }
        _ => {
            return Err(Error::corrupt(format!(
                "PNG header has invalid colour type {} / bit depth {}",
                h.colour_type, h.bit_depth
            )));
        }
    };
    let sidecar_says = mapping
        .filter(|m| m.nodata_code.is_none())
        .and_then(|m| RgbHeights::of_mapping(&m.value_mapping()));
    let encoding = rgb.or(sidecar_says);
    if is_rgb && encoding.is_none() {
        // Colour PNGs are pictures far more often than height maps: reading one as heights
        // is a choice the caller makes.
        return Err(Error::unsupported(format!(
            "{desc} PNG: vtz reads colour PNGs only as Mapbox Terrain-RGB or Terrarium heights; if it is one, say so with --format terrain-rgb or --format terrarium"
        )));
    }
    if let (Some(k), false) = (rgb, is_rgb) {
        return Err(Error::unsupported(format!(
            "{} needs an 8-bit RGB or RGBA PNG, this one is {desc}",
            k.name()
        )));
    }
    let n = check_size(h.width as u64, h.height as u64, opts.max_samples())?;
    let (width, height) = (h.width as usize, h.height as usize);

    let mut limits = image::Limits::default();
    limits.max_alloc = Some(64 << 20); // metadata chunks only: the pixel buffer is ours
    let decoder = PngDecoder::with_limits(Cursor::new(bytes), limits).map_err(image_error)?;
    let ct = decoder.color_type();
    let total = usize::try_from(decoder.total_bytes())
        .map_err(|_| Error::limit("PNG image too large for this platform"))?;
    let channels = ct.channel_count() as usize;
    let bpc = ct.bytes_per_pixel() as usize / channels;
    if total != n * channels * bpc {
        return Err(Error::corrupt("PNG decoder disagrees with the PNG header"));
    }
    let mut buf = vec![0u8; total];
    decoder.read_image(&mut buf).map_err(image_error)?;

    let mut data = Vec::with_capacity(n);
    let mut mask: Option<Vec<bool>> = None;

    if let (true, Some(k)) = (is_rgb, encoding) {
        let alpha = match ct {
            ColorType::Rgb8 => false,
            ColorType::Rgba8 => true,
            other => {
                return Err(Error::unsupported(format!(
                    "PNG decodes as {other:?}, not 8-bit RGB/RGBA"
                )));
            }
        };
        for (i, px) in buf.chunks_exact(channels).enumerate() {
            if alpha && px[3] == 0 {
                mark_invalid(&mut mask, n, i);
                data.push(f64::NAN);
            } else {
                let code = (px[0] as u32) << 16 | (px[1] as u32) << 8 | px[2] as u32;
                data.push(k.value(code));
            }
        }
        return Ok(Raster {
            mapping: k.mapping(),
            ..Raster::from_parts(width, height, data, mask, None, SampleType::F32)
        });
    }

    let m = mapping.cloned().unwrap_or(PngMapping {
        scale: 1.0,
        offset: 0.0,
        nodata_code: None,
    });
    check_mapping(m.scale, m.offset)?;
    let vm = m.value_mapping();
    let (sixteen, alpha) = match ct {
        ColorType::L8 => (false, false),
        ColorType::La8 => (false, true),
        ColorType::L16 => (true, false),
        ColorType::La16 => (true, true),
        other => {
            return Err(Error::unsupported(format!(
                "PNG decodes as {other:?}, not 8/16-bit greyscale"
            )));
        }
    };
    let nodata = m.nodata_code.map(|c| vm.to_value(c as f64));
    let fill = nodata.unwrap_or(f64::NAN);
    let px_bytes = channels * bpc;
    for (i, px) in buf.chunks_exact(px_bytes).enumerate() {
        let (code, a) = if sixteen {
            let c = u16::from_ne_bytes([px[0], px[1]]);
            let a = if alpha {
                u16::from_ne_bytes([px[2], px[3]])
            } else {
                1
            };
            (c, a)
        } else {
            (px[0] as u16, if alpha { px[1] as u16 } else { 1 })
        };
        if a == 0 || Some(code) == m.nodata_code {
            mark_invalid(&mut mask, n, i);
            data.push(fill);
        } else {
            let v = vm.to_value(code as f64);
            if Some(v) == nodata {
                return Err(Error::invalid(format!(
                    "PNG mapping gives code {code} the same value {v} as the nodata code"
                )));
            }
            data.push(v);
        }
    }
    let sample_type = if sixteen {
        SampleType::U16
    } else {
        SampleType::U8
    };
    Ok(Raster {
        mapping: vm,
        ..Raster::from_parts(width, height, data, mask, nodata, sample_type)
    })
}

/// Codes of SRTM-like heights + 32768 (16-bit PNGs of terrain often store `metres + 32768`,
/// voids as 0): the deepest trench and the highest peak on either side of 32768.
const OFFSET_CODES: std::ops::RangeInclusive<f64> = 21_000.0..=42_000.0;

/// A note for a 16-bit grey PNG read without a mapping whose valid codes (0 aside) all sit
/// around 32768, as heights + 32768 do: what `--png-offset -32768 --png-nodata 0` would read
/// instead. The data is read as the codes either way.
pub(crate) fn offset_note(r: &Raster) -> Option<String> {
    if r.sample_type != SampleType::U16 || !r.mapping.is_identity() {
        return None;
    }
    let (mut lo, mut hi, mut zeros) = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
    for (i, &v) in r.data.iter().enumerate() {
        if !r.is_valid(i) {
            continue;
        }
        if v == 0.0 {
            zeros += 1;
            continue;
        }
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !(OFFSET_CODES.contains(&lo) && OFFSET_CODES.contains(&hi)) {
        return None;
    }
    let voids = match zeros {
        0 => String::new(),
        1 => " and code 0 (1 sample here) as nodata".to_string(),
        n => format!(" and code 0 ({n} samples here) as nodata"),
    };
    Some(format!(
        "this 16-bit PNG's codes ({lo}…{hi}) sit around 32768, as heights + 32768 do (SRTM \
         PNGs); they are read as they are, with no nodata: --png-offset -32768 --png-nodata 0 \
         would read them as {}…{} m{voids}",
        lo - 32768.0,
        hi - 32768.0
    ))
}

/// The code in `lo..=hi` nearest `approx` whose decoded value is closest to `v`.
fn best_code(approx: f64, lo: u32, hi: u32, v: f64, decode: impl Fn(u32) -> f64) -> u32 {
    let c = approx.round().clamp(lo as f64, hi as f64) as u32;
    let mut best = c;
    let mut err = (decode(c) - v).abs();
    for cand in [c.saturating_sub(1).max(lo), (c + 1).min(hi)] {
        let e = (decode(cand) - v).abs();
        if e < err {
            best = cand;
            err = e;
        }
    }
    best
}

fn encode_png(buf: &[u8], r: &Raster, ct: ExtendedColorType) -> Result<Vec<u8>> {
    let (w, h) = match (u32::try_from(r.width), u32::try_from(r.height)) {
        (Ok(w), Ok(h)) if w < 1 << 31 && h < 1 << 31 => (w, h),
        _ => {
            return Err(Error::invalid(format!(
                "raster {}x{} is too large for a PNG",
                r.width, r.height
            )));
        }
    };
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Default, FilterType::Adaptive)
        .write_image(buf, w, h, ct)
        .map_err(|e| Error::invalid(format!("PNG encoding failed: {e}")))?;
    Ok(out)
}

/// Write a greyscale PNG (16-bit; 8-bit for u8 rasters whose codes fit) and, when the
/// mapping is not the identity or there is a nodata code or a georef, its sidecar bytes.
///
/// The mapping is `mapping` if given, else the raster's own. Codes are
/// `round((value - offset) / scale)` and must fit 0..=65535. Invalid samples get the
/// mapping's `nodata_code`, else the code of the raster's declared nodata value, else code
/// 0 or 65535 or another code no valid sample uses.
///
/// Also gives the mapping (with the nodata code) the codes were written with, which the PAM
/// file tells GDAL.
pub(crate) fn write_mapped(
    r: &Raster,
    mapping: Option<&PngMapping>,
    round: bool,
) -> Result<(Vec<u8>, Option<Vec<u8>>, PngMapping)> {
    let (scale, offset, mut nodata_code) = match mapping {
        Some(m) => (m.scale, m.offset, m.nodata_code),
        None => (r.mapping.scale, r.mapping.offset, None),
    };
    check_mapping(scale, offset)?;
    let vm = ValueMapping { scale, offset };
    let decode = |c: u32| vm.to_value(c as f64);
    let n = r.len();
    let mut codes = vec![0u16; n];
    let mut used = vec![false; 65536];
    let mut worst = Rounding::default();
    for (i, &v) in r.data.iter().enumerate() {
        if !r.is_valid(i) {
            continue;
        }
        let approx = vm.to_code(v);
        if !(approx.round() >= 0.0 && approx.round() <= 65535.0) {
            return Err(Error::invalid(format!(
                "sample {i} (row {}, col {}) = {v} maps to PNG code {} outside 0..=65535 with offset {offset}, scale {scale} (value = offset + scale·code); choose another --png-offset/--png-scale",
                i / r.width,
                i % r.width,
                approx.round()
            )));
        }
        let c = best_code(approx, 0, 65535, v, decode) as u16;
        worst.note(i, v, decode(c as u32));
        codes[i] = c;
        used[c as usize] = true;
    }
    worst.check(
        r,
        round,
        &format!("16-bit PNG codes (value = {offset} + {scale}·code)"),
        KEEP_HINT,
    )?;
    let has_invalid = r.valid_count() < n;
    if nodata_code.is_none() {
        if let Some(nd) = r.nodata {
            let c = vm.to_code(nd).round();
            if (0.0..=65535.0).contains(&c) && decode(c as u32) == nd {
                nodata_code = Some(c as u16);
            }
        }
    }
    if nodata_code.is_none() && has_invalid {
        nodata_code = [0u16, 65535]
            .into_iter()
            .chain(1..65535)
            .find(|&c| !used[c as usize]);
        if nodata_code.is_none() {
            return Err(Error::invalid(
                "every PNG code is taken by valid samples: no code left to mark nodata",
            ));
        }
    }
    if let Some(nc) = nodata_code {
        if used[nc as usize] {
            let i = (0..n)
                .find(|&i| r.is_valid(i) && codes[i] == nc)
                .unwrap_or(0);
            return Err(Error::invalid(format!(
                "sample {i} (row {}, col {}) = {} maps to the nodata code {nc}",
                i / r.width,
                i % r.width,
                r.data[i]
            )));
        }
        if has_invalid {
            for (i, c) in codes.iter_mut().enumerate() {
                if !r.is_valid(i) {
                    *c = nc;
                }
            }
        }
    }
    let max_code = codes
        .iter()
        .copied()
        .max()
        .unwrap_or(0)
        .max(nodata_code.unwrap_or(0));
    let png = if r.sample_type == SampleType::U8 && max_code <= 255 {
        let buf: Vec<u8> = codes.iter().map(|&c| c as u8).collect();
        encode_png(&buf, r, ExtendedColorType::L8)?
    } else {
        let buf: Vec<u8> = codes.iter().flat_map(|c| c.to_ne_bytes()).collect();
        encode_png(&buf, r, ExtendedColorType::L16)?
    };
    let m = PngMapping {
        scale,
        offset,
        nodata_code,
    };
    let sidecar = if !vm.is_identity() || nodata_code.is_some() || r.georef.is_some() {
        Some(sidecar_bytes(&m, r.georef.as_ref())?)
    } else {
        None
    };
    Ok((png, sidecar, m))
}

/// Where the rounding message of a PNG writer points.
const KEEP_HINT: &str = ", choose --png-scale/--png-offset, or write .tif, which keeps the values";

/// Write a Mapbox Terrain-RGB PNG (RGBA8, alpha 255; invalid samples are (0, 0, 0, 0)),
/// plus a sidecar holding the georef when the raster has one.
#[cfg(test)]
fn write_terrain_rgb(r: &Raster, round: bool) -> Result<(Vec<u8>, Option<Vec<u8>>)> {
    write_rgb_heights(r, RgbHeights::TerrainRgb, round)
}

/// Write an RGBA8 PNG of heights in encoding `k` (alpha 255; invalid samples are
/// (0, 0, 0, 0)), plus a sidecar naming the encoding and holding the georef when the raster
/// has one. A value the encoding cannot hold exactly is refused unless `round`.
pub fn write_rgb_heights(
    r: &Raster,
    k: RgbHeights,
    round: bool,
) -> Result<(Vec<u8>, Option<Vec<u8>>)> {
    let m = k.mapping();
    let mut buf = Vec::with_capacity(r.len() * 4);
    let mut worst = Rounding::default();
    for (i, &v) in r.data.iter().enumerate() {
        if !r.is_valid(i) {
            buf.extend_from_slice(&[0, 0, 0, 0]);
            continue;
        }
        let approx = m.to_code(v).round();
        if !(approx >= 0.0 && approx <= TRGB_MAX_CODE as f64) {
            return Err(Error::invalid(format!(
                "sample {i} (row {}, col {}) = {v} is outside the {} range {}..={}",
                i / r.width,
                i % r.width,
                k.name(),
                k.value(0),
                k.value(TRGB_MAX_CODE)
            )));
        }
        let c = best_code(approx, 0, TRGB_MAX_CODE, v, |c| k.value(c));
        worst.note(i, v, k.value(c));
        buf.extend_from_slice(&[(c >> 16) as u8, (c >> 8) as u8, c as u8, 255]);
    }
    let steps = match k {
        RgbHeights::TerrainRgb => "Terrain-RGB's 0.1 steps",
        RgbHeights::Terrarium => "Terrarium's 1/256 steps",
    };
    worst.check(r, round, steps, KEEP_HINT)?;
    let png = encode_png(&buf, r, ExtendedColorType::Rgba8)?;
    let sidecar = match &r.georef {
        Some(g) => Some(sidecar_bytes(
            &PngMapping {
                scale: m.scale,
                offset: m.offset,
                nodata_code: None,
            },
            Some(g),
        )?),
        None => None,
    };
    Ok((png, sidecar))
}

/// [`write_mapped`] without the mapping.
#[cfg(test)]
fn write(
    r: &Raster,
    mapping: Option<&PngMapping>,
    round: bool,
) -> Result<(Vec<u8>, Option<Vec<u8>>)> {
    write_mapped(r, mapping, round).map(|(png, sidecar, _)| (png, sidecar))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::{Format, WriteOptions, read_path, write_path};
    use crate::model::RasterType;
    use crate::testutil::*;

    fn opts() -> ReadOptions {
        ReadOptions::default()
    }

    /// Decode a PNG with `image` into (color type, raw samples as u32).
    fn pixels(png: &[u8]) -> (ColorType, Vec<u32>) {
        let d = PngDecoder::new(Cursor::new(png)).unwrap();
        let ct = d.color_type();
        let mut buf = vec![0u8; d.total_bytes() as usize];
        d.read_image(&mut buf).unwrap();
        let bpc = ct.bytes_per_pixel() / ct.channel_count();
        let v = if bpc == 2 {
            buf.chunks_exact(2)
                .map(|c| u16::from_ne_bytes([c[0], c[1]]) as u32)
                .collect()
        } else {
            buf.iter().map(|&b| b as u32).collect()
        };
        (ct, v)
    }

    fn grey16(w: u32, h: u32, codes: &[u16]) -> Vec<u8> {
        let buf: Vec<u8> = codes.iter().flat_map(|c| c.to_ne_bytes()).collect();
        let mut out = Vec::new();
        PngEncoder::new(&mut out)
            .write_image(&buf, w, h, ExtendedColorType::L16)
            .unwrap();
        out
    }

    #[test]
    fn small_grey16_mapping() {
        let png = grey16(3, 2, &[0, 1, 2, 32768, 65535, 0]);
        let m = PngMapping {
            scale: 0.5,
            offset: -100.0,
            nodata_code: Some(0),
        };
        let r = read(&png, Some(&m), None, &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::U16);
        assert_eq!(r.nodata, Some(-100.0));
        assert_eq!(r.data, [-100.0, -99.5, -99.0, 16284.0, 32667.5, -100.0]);
        assert_eq!(
            r.mask.as_deref(),
            Some(&[false, true, true, true, true, false][..])
        );
        assert_eq!(
            r.mapping,
            ValueMapping {
                scale: 0.5,
                offset: -100.0
            }
        );
        // Writing with the raster's own mapping: nodata code comes from the declared nodata.
        let (out, side) = write(&r, None, false).unwrap();
        assert_eq!(pixels(&out).1, pixels(&png).1);
        let s = parse_sidecar(&side.unwrap(), "test").unwrap();
        assert_eq!(s.mapping, m);
        assert!(s.georef.is_none());
        let back = read(&out, Some(&s.mapping), None, &opts()).unwrap();
        assert_same(&r, &back, "png round trip");
        // Forcing Terrain-RGB on a grey PNG is refused.
        assert!(matches!(
            read(&png, None, Some(RgbHeights::TerrainRgb), &opts()),
            Err(Error::Unsupported { .. })
        ));
    }

    #[test]
    fn identity_has_no_sidecar() {
        let r =
            Raster::from_values(2, 2, vec![1.0, 2.0, 3.0, 65535.0], None, SampleType::U16).unwrap();
        let (png, side) = write(&r, None, false).unwrap();
        assert!(side.is_none());
        assert_same(
            &r,
            &read(&png, None, None, &opts()).unwrap(),
            "png round trip",
        );
        // u8 rasters are written as 8-bit grey and read back as u8.
        let r = Raster::from_values(2, 1, vec![0.0, 255.0], None, SampleType::U8).unwrap();
        let (png, side) = write(&r, None, false).unwrap();
        assert!(side.is_none());
        assert_eq!(pixels(&png).0, ColorType::L8);
        assert_same(
            &r,
            &read(&png, None, None, &opts()).unwrap(),
            "png round trip",
        );
    }

    #[test]
    fn write_picks_nodata_code_and_checks_range() {
        let r = Raster::from_values(3, 1, vec![0.0, f64::NAN, 7.0], None, SampleType::U16).unwrap();
        let (png, side) = write(&r, None, false).unwrap();
        let s = parse_sidecar(&side.unwrap(), "t").unwrap();
        assert_eq!(s.mapping.nodata_code, Some(65535));
        assert_eq!(pixels(&png).1, [0, 65535, 7]);
        let back = read(&png, Some(&s.mapping), None, &opts()).unwrap();
        assert_eq!(back.mask, r.mask);
        let r = Raster::from_values(2, 1, vec![-1.0, 3.0], None, SampleType::I16).unwrap();
        match write(&r, None, false) {
            Err(Error::InvalidArgument { what }) => {
                assert!(what.contains("--png-offset"), "{what}")
            }
            other => panic!("{other:?}"),
        }
        let m = PngMapping {
            scale: 1.0,
            offset: -10.0,
            nodata_code: Some(9),
        };
        // value -1 → code 9 = the nodata code
        assert!(matches!(
            write(&r, Some(&m), false),
            Err(Error::InvalidArgument { .. })
        ));
        let m = PngMapping {
            scale: 0.0,
            offset: 0.0,
            nodata_code: None,
        };
        assert!(matches!(
            write(&r, Some(&m), false),
            Err(Error::InvalidArgument { .. })
        ));
    }

    #[test]
    fn terrain_rgb_roundtrip() {
        let mut rng = Rng(3);
        let (w, h) = (17, 9);
        let data = with_holes(w * h, 11, 0, |_| trgb_value((rng.next() % 300_000) as u32));
        let mut r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
        r.georef = Some(Georef {
            origin: [0.1, 0.2],
            pixel_size: [0.3, 0.3],
            raster_type: RasterType::Area,
            epsg: Some(3857),
            wkt: None,
            geokeys: None,
        });
        let (png, side) = write_terrain_rgb(&r, false).unwrap();
        let s = parse_sidecar(&side.unwrap(), "t").unwrap();
        // A colour PNG is heights only when the caller or vtz's own sidecar says so.
        let refused = read(&png, None, None, &opts()).unwrap_err().to_string();
        assert!(refused.contains("--format terrain-rgb"), "{refused}");
        let mut back = read(&png, Some(&s.mapping), None, &opts()).unwrap();
        assert_same(
            &back,
            &read(&png, None, Some(RgbHeights::TerrainRgb), &opts()).unwrap(),
            "sidecar or flag",
        );
        assert_eq!(back.mapping, TERRAIN_RGB);
        back.georef = s.georef;
        assert_same(&r, &back, "png round trip");
        let r = Raster::from_values(1, 1, vec![-10000.1], None, SampleType::F32).unwrap();
        assert!(matches!(
            write_terrain_rgb(&r, false),
            Err(Error::InvalidArgument { .. })
        ));
    }

    /// Terrarium (`code / 256 - 32768`) is read exactly, told by the flag or by vtz's sidecar,
    /// and written back to the same pixels; the offset note speaks only of 16-bit grey codes
    /// around 32768.
    #[test]
    fn terrarium_roundtrip_and_the_offset_note() {
        let (w, h) = (7, 4);
        let data: Vec<f64> = (0..w * h)
            .map(|i| -32768.0 + (i as f64) * 2345.5 + (i % 5) as f64 / 256.0)
            .collect();
        let mut r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
        r.mapping = TERRARIUM;
        let (png, side) = write_rgb_heights(&r, RgbHeights::Terrarium, false).unwrap();
        assert!(side.is_none(), "no georef, no sidecar");
        let back = read(&png, None, Some(RgbHeights::Terrarium), &opts()).unwrap();
        assert_eq!(back.mapping, TERRARIUM);
        assert_same(&r, &back, "terrarium");
        let (_, px) = pixels(&png);
        let code = px[4] << 16 | px[5] << 8 | px[6];
        assert_eq!(code, 2345 * 256 + 128 + 1, "sample 1's code, RGBA");
        let m = PngMapping {
            scale: TERRARIUM.scale,
            offset: TERRARIUM.offset,
            nodata_code: None,
        };
        assert_same(
            &back,
            &read(&png, Some(&m), None, &opts()).unwrap(),
            "sidecar",
        );
        let e = read(&png, None, None, &opts()).unwrap_err().to_string();
        assert!(e.contains("--format terrarium"), "{e}");

        let codes =
            |v: Vec<f64>| Raster::from_values(v.len(), 1, v, None, SampleType::U16).unwrap();
        let note = offset_note(&codes(vec![32731.0, 0.0, 34254.0])).unwrap();
        assert!(note.contains("(32731…34254)"), "{note}");
        assert!(
            note.contains("-37…1486 m and code 0 (1 sample here) as nodata"),
            "{note}"
        );
        assert_eq!(offset_note(&codes(vec![100.0, 34254.0])), None);
        let mut mapped = codes(vec![32731.0, 34254.0]);
        mapped.mapping = ValueMapping {
            scale: 1.0,
            offset: -32768.0,
        };
        assert_eq!(offset_note(&mapped), None);
    }

    #[test]
    fn unsupported_kinds() {
        let mut out = Vec::new();
        PngEncoder::new(&mut out)
            .write_image(&[0u8; 6], 1, 1, ExtendedColorType::Rgb16)
            .unwrap();
        match read(&out, None, None, &opts()) {
            Err(Error::Unsupported { what }) => assert!(what.contains("16-bit RGB"), "{what}"),
            other => panic!("{other:?}"),
        }
        let mut pal = grey16(1, 1, &[5]);
        pal[24] = 8;
        pal[25] = 3; // colour type 3 = palette (the CRC no longer matters: refused first)
        match read(&pal, None, None, &opts()) {
            Err(Error::Unsupported { what }) => assert!(what.contains("palette"), "{what}"),
            other => panic!("{other:?}"),
        }
        // grey+alpha is read with alpha 0 = nodata
        let mut out = Vec::new();
        PngEncoder::new(&mut out)
            .write_image(&[10, 255, 20, 0], 2, 1, ExtendedColorType::La8)
            .unwrap();
        let r = read(&out, None, None, &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::U8);
        assert_eq!(r.mask.as_deref(), Some(&[true, false][..]));
    }

    #[test]
    fn garbage_and_limits() {
        let png = grey16(4, 3, &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
        // Every cut before the 12-byte IEND chunk fails (after it, the pixels are complete).
        for cut in 0..png.len() {
            let res = read(&png[..cut], None, None, &opts());
            assert!(res.is_err() || cut >= png.len() - 12, "cut {cut}");
        }
        let mut rng = Rng(11);
        for len in [0, 8, 33, 100, 1000] {
            assert!(read(&rng.bytes(len), None, None, &opts()).is_err());
        }
        // Flip bytes in the data: errors, never panics.
        for k in 0..200 {
            let mut b = png.clone();
            let i = 8 + (rng.next() as usize) % (b.len() - 8);
            b[i] ^= 1 << (k % 8);
            let _ = read(&b, None, None, &opts());
        }
        let mut big = png.clone();
        big[16..20].copy_from_slice(&100_000u32.to_be_bytes());
        big[20..24].copy_from_slice(&100_000u32.to_be_bytes());
        assert!(matches!(
            read(&big, None, None, &opts()),
            Err(Error::LimitExceeded { .. })
        ));
        assert!(matches!(
            parse_sidecar(b"{\"scale\": 0}", "t"),
            Err(Error::Corrupt { .. })
        ));
        assert!(parse_sidecar(b"[1, 2]", "t").is_err());
        assert!(parse_sidecar(b"{\"nodata_code\": 70000}", "t").is_err());
    }

    #[test]
    fn corpus_scape_pngs() {
        let names = ["scape_crater", "scape_ashby", "scape_ozark"];
        for_each_corpus(&names, |dir, name| {
            let bytes = std::fs::read(dir.join(format!("{name}.png"))).unwrap();
            let r = read(&bytes, None, None, &opts()).unwrap();
            assert_eq!(r.sample_type, SampleType::U16);
            assert_eq!(raster_bits(&r), raw_bits(dir, name), "{name}");
            let (png, side) = write(&r, None, false).unwrap();
            assert!(side.is_none());
            assert_eq!(pixels(&png), pixels(&bytes), "{name}: codes differ");
            assert_same(
                &r,
                &read(&png, None, None, &opts()).unwrap(),
                "png round trip",
            );
        });
    }

    #[test]
    fn corpus_istria_via_paths() {
        let Some(dir) = corpus() else { return };
        let name = "srtm1_N45E013_istria_crop2400";
        let src = dir.join(format!("{name}.png"));
        let m = PngMapping {
            scale: 1.0,
            offset: -32768.0,
            nodata_code: Some(0),
        };
        let ro = ReadOptions {
            png_mapping: Some(m.clone()),
            ..Default::default()
        };
        let mut r = read_path(&src, &ro).unwrap();
        assert_eq!(raster_bits(&r), raw_bits(&dir, name));
        assert_eq!(r.nodata, Some(-32768.0));
        r.georef = Some(Georef {
            origin: [13.0 + 1200.5 / 3600.0, 46.0 - 600.5 / 3600.0],
            pixel_size: [1.0 / 3600.0, 1.0 / 3600.0],
            raster_type: RasterType::Point,
            epsg: Some(4326),
            wkt: None,
            geokeys: None,
        });
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("istria.png");
        write_path(&r, &out, &WriteOptions::default()).unwrap();
        let side = read_sidecar(&out).unwrap().unwrap();
        assert_eq!(side.mapping, m);
        assert_eq!(side.georef, r.georef);
        let back = read_path(&out, &ReadOptions::default()).unwrap();
        assert_same(&r, &back, "png round trip");
        assert_eq!(back.mapping, r.mapping);
        let orig = std::fs::read(&src).unwrap();
        assert_eq!(pixels(&std::fs::read(&out).unwrap()), pixels(&orig));
    }

    #[test]
    fn corpus_fuji_terrain_rgb() {
        let Some(dir) = corpus() else { return };
        let name = "mapbox_fuji_terrainrgb";
        let src = dir.join(format!("{name}.png"));
        let bytes = std::fs::read(&src).unwrap();
        let r = read(&bytes, None, Some(RgbHeights::TerrainRgb), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::F32);
        assert_eq!(r.mapping, TERRAIN_RGB);
        assert_eq!(raster_bits(&r), raw_bits(&dir, name));
        let forced = ReadOptions {
            format: Some(Format::TerrainRgb),
            ..Default::default()
        };
        assert_same(&r, &read_path(&src, &forced).unwrap(), "png round trip");
        let (png, side) = write_terrain_rgb(&r, false).unwrap();
        assert!(side.is_none());
        let back = read(&png, None, Some(RgbHeights::TerrainRgb), &opts()).unwrap();
        assert_same(&r, &back, "png round trip");
        // Same RGB codes as the source (alpha is 255 in both).
        assert_eq!(pixels(&png), pixels(&bytes));
    }
}
