//! Raw little-endian f32 rasters (`NAME.f32`) with a `NAME.json` sidecar: the corpus storage format.
//!
//! The `.f32` file holds `width × height` little-endian `f32` values, row-major, row 0 = north
//! (south when the georef's `pixel_size[1]` is negative, as the sidecar's `row_order` then
//! says), no header. The json sidecar holds `width`, `height`, `source_dtype`, `nodata`, `dx`, `dy`
//! and, when vtz wrote it, a `georef` object and an optional `value_mapping`
//! (`{"scale": s, "offset": o}`). The file holds the values themselves (metres, not PNG
//! codes); `source_dtype` is the type of the integer codes they came from, through
//! `value_mapping` when there is one (`value = offset + scale·code`), and the reader keeps
//! it only when every value is such a code. The georef object, and the exact form of its floats, are
//! those of [`crate::formats::sidecar`] (shared with the PNG sidecar and the EXR
//! `vtz_georef` attribute).
//! Corpus sidecars have no `georef` object; their georeferencing is rebuilt from the
//! free-text `origin` and `units` fields where that text is unambiguous.

use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::formats::samples::valid_f32;
use crate::formats::sidecar::{ExactF64, GeorefJson, expect_json_object};
use crate::model::{Georef, Raster, RasterType, SampleType, ValueMapping, check_size};
use serde::{Deserialize, Serialize};

/// JSON form of [`ValueMapping`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct MappingJson {
    scale: ExactF64,
    offset: ExactF64,
}

/// The sidecar fields the reader uses (each optional); everything else in a corpus sidecar
/// is ignored.
#[derive(Default, Deserialize)]
#[serde(default)]
struct RawJsonIn {
    width: Option<serde_json::Value>,
    height: Option<serde_json::Value>,
    source_dtype: Option<serde_json::Value>,
    nodata: Option<ExactF64>,
    dx: Option<serde_json::Value>,
    dy: Option<serde_json::Value>,
    units: Option<serde_json::Value>,
    origin: Option<serde_json::Value>,
    georef: Option<GeorefJson>,
    value_mapping: Option<MappingJson>,
}

#[derive(Serialize)]
struct RawJsonOut<'a> {
    width: usize,
    height: usize,
    source_dtype: &'a str,
    nodata: Option<ExactF64>,
    dx: Option<ExactF64>,
    dy: Option<ExactF64>,
    row_order: &'a str,
    georef: Option<GeorefJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    value_mapping: Option<MappingJson>,
}

/// Sample type from a free-text `source_dtype` ("int16 (big-endian, SRTM .hgt)", "uint16",
/// "float32 (GeoTIFF, LZW)", vtz's own "i16", ...): the first word naming a type wins.
/// Values are stored as f32, so float64 sources count as F32; unknown text means F32.
pub(crate) fn sample_type_from_text(text: &str) -> SampleType {
    for word in text
        .split(|c: char| !c.is_ascii_alphanumeric())
        .map(|w| w.to_ascii_lowercase())
    {
        let t = match word.as_str() {
            "uint8" | "u8" | "byte" => SampleType::U8,
            "int16" | "i16" => SampleType::I16,
            "uint16" | "u16" => SampleType::U16,
            "int32" | "i32" => SampleType::I32,
            "float32" | "f32" | "float64" | "f64" | "double" | "float" => SampleType::F32,
            _ => continue,
        };
        return t;
    }
    SampleType::F32
}

/// The number following `key` in `text` (lowercase), where `key` stands as a word of its own
/// and is followed by spaces, `=` or `:`.
fn number_after(text: &str, key: &str) -> Option<f64> {
    let bytes = text.as_bytes();
    let mut from = 0;
    while let Some(pos) = text[from..].find(key) {
        let start = from + pos;
        let end = start + key.len();
        from = start + 1;
        if start > 0 && bytes[start - 1].is_ascii_alphanumeric() {
            continue;
        }
        let rest = &text[end..];
        let rest_trim = rest.trim_start_matches([' ', '=', ':', '\t']);
        if rest_trim.len() == rest.len() && !key.ends_with('=') {
            // "lon" directly followed by letters ("longitude") is not our key.
            continue;
        }
        let num: String = rest_trim
            .chars()
            .take_while(|c| c.is_ascii_digit() || matches!(c, '-' | '+' | '.' | 'e'))
            .collect();
        let num = num.trim_end_matches(['.', 'e']);
        if let Ok(v) = num.parse::<f64>() {
            return Some(v);
        }
    }
    None
}

/// EPSG code from a corpus `units` text: an explicit "EPSG:n", a UTM zone on WGS84, or
/// geographic degrees (NAD83 → 4269, otherwise WGS84 → 4326).
fn epsg_from_units(units: &str) -> Option<u32> {
    let u = units.to_ascii_lowercase();
    if let Some(p) = u.find("epsg:") {
        let digits: String = u[p + 5..]
            .chars()
            .take_while(|c| c.is_ascii_digit())
            .collect();
        if let Ok(code) = digits.parse::<u32>() {
            return Some(code);
        }
    }
    if let Some(p) = u.find("utm zone ") {
        let rest = &u[p + 9..];
        let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
        let zone: u32 = digits.parse().ok()?;
        let hemi = rest[digits.len()..].chars().next();
        if (1..=60).contains(&zone) && u.contains("wgs84") {
            return match hemi {
                Some('n') => Some(32600 + zone),
                Some('s') => Some(32700 + zone),
                _ => None,
            };
        }
        return None;
    }
    if u.contains("degree") {
        return Some(if u.contains("nad83") { 4269 } else { 4326 });
    }
    None
}

/// Georeferencing from a corpus sidecar's free text: `origin` says "upper-left corner
/// lon X, lat Y" / "upper-left corner x=X, y=Y" (or "NW corner", "lower-left corner")
/// for [`RasterType::Area`], or "cell centre of row 0, col 0 = lat Y, lon X" for
/// [`RasterType::Point`]. Approximate origins ("approx") give no georef.
fn georef_from_text(origin: &str, units: &str, dx: f64, dy: f64, height: usize) -> Option<Georef> {
    if !(dx.is_finite() && dy.is_finite() && dx > 0.0 && dy > 0.0) {
        return None;
    }
    let o = origin.to_ascii_lowercase();
    if o.contains("approx") {
        return None;
    }
    enum Kind {
        UpperLeft,
        LowerLeft,
        Centre,
    }
    // The centre form mentions "NW corner" in its remarks, so it is tested first.
    let kind =
        if o.contains("cell centre of row 0, col 0") || o.contains("cell center of row 0, col 0") {
            Kind::Centre
        } else if o.contains("upper-left corner") || o.contains("nw corner") {
            Kind::UpperLeft
        } else if o.contains("lower-left corner") || o.contains("sw corner") {
            Kind::LowerLeft
        } else {
            return None;
        };
    let x = number_after(&o, "lon").or_else(|| number_after(&o, "x="))?;
    let y = number_after(&o, "lat").or_else(|| number_after(&o, "y="))?;
    let (origin, raster_type) = match kind {
        Kind::UpperLeft => ([x, y], RasterType::Area),
        Kind::LowerLeft => ([x, y + height as f64 * dy], RasterType::Area),
        Kind::Centre => ([x, y], RasterType::Point),
    };
    Some(Georef {
        origin,
        pixel_size: [dx, dy],
        raster_type,
        epsg: epsg_from_units(units),
        wkt: None,
        geokeys: None,
    })
}

fn json_usize(v: &Option<serde_json::Value>, name: &str) -> Result<u64> {
    v.as_ref().and_then(|v| v.as_u64()).ok_or_else(|| {
        Error::corrupt(format!(
            "raw sidecar json: '{name}' is missing or not a non-negative integer"
        ))
    })
}

fn json_f64(v: &Option<serde_json::Value>) -> Option<f64> {
    v.as_ref().and_then(|v| v.as_f64())
}

fn json_text(v: &Option<serde_json::Value>) -> &str {
    v.as_ref().and_then(|v| v.as_str()).unwrap_or("")
}

/// Read a raw f32 raster from the `.f32` bytes and its json sidecar.
pub fn read(bytes: &[u8], json: &[u8], opts: &ReadOptions) -> Result<Raster> {
    expect_json_object(json, "raw sidecar json")?;
    let meta: RawJsonIn = serde_json::from_slice(json)
        .map_err(|e| Error::corrupt(format!("raw sidecar json: {e}")))?;
    let w = json_usize(&meta.width, "width")?;
    let h = json_usize(&meta.height, "height")?;
    let n = check_size(w, h, opts.max_samples())?;
    let (width, height) = (w as usize, h as usize);
    let expected = n as u64 * 4;
    if bytes.len() as u64 != expected {
        return Err(Error::corrupt(format!(
            "raw f32 data has {} bytes, but {width}x{height} samples need {expected}",
            bytes.len()
        )));
    }
    let nodata32 = meta.nodata.map(|v| v.0 as f32);
    if nodata32.is_some_and(f32::is_nan) {
        return Err(Error::corrupt("raw sidecar json: nodata is NaN"));
    }
    let mapping = mapping_of(&meta)?;
    let mut data = Vec::with_capacity(n);
    // Range of the valid values, whether they are all integers, and whether they all are
    // whole codes of the value mapping.
    let (mut lo, mut hi, mut all_int) = (f64::INFINITY, f64::NEG_INFINITY, true);
    let mut codes_int = true;
    for (i, c) in bytes.chunks_exact(4).enumerate() {
        let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        let is_nodata = nodata32.is_some_and(|nd| v == nd);
        if !is_nodata && !v.is_nan() {
            if v.is_infinite() {
                return Err(Error::corrupt(format!(
                    "raw f32 sample {i} (row {}, col {}) is infinite",
                    i / width,
                    i % width
                )));
            }
            let d = v as f64;
            lo = lo.min(d);
            hi = hi.max(d);
            all_int &= d.fract() == 0.0;
            codes_int &= mapping.is_none_or(|m| is_code(m, d));
        }
        data.push(v as f64);
    }
    let (st, mapping, georef) = band_meta(&meta, height, lo, hi, all_int, codes_int)?;
    let mut r = Raster::from_values(width, height, data, nodata32.map(|v| v as f64), st)?;
    if let Some(m) = mapping {
        r.mapping = m;
    }
    r.georef = georef;
    Ok(r)
}

/// What a raw raster's sidecar and the range of its values decide: the sample type, the
/// value mapping and the georef (for a raster of `height` rows).
/// The sidecar's value mapping, checked.
fn mapping_of(meta: &RawJsonIn) -> Result<Option<ValueMapping>> {
    Ok(match &meta.value_mapping {
        Some(m) => {
            let (scale, offset) = (m.scale.0, m.offset.0);
            if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
                return Err(Error::corrupt(format!(
                    "raw sidecar json: value_mapping scale {scale} / offset {offset} is not usable"
                )));
            }
            Some(ValueMapping { scale, offset })
        }
        None => None,
    })
}

/// Whether the value `v` is a whole code of the mapping `m` (`v = offset + scale·code`).
fn is_code(m: ValueMapping, v: f64) -> bool {
    let c = (v - m.offset) / m.scale;
    c.fract() == 0.0 && m.offset + m.scale * c == v
}

fn band_meta(
    meta: &RawJsonIn,
    height: usize,
    lo: f64,
    hi: f64,
    all_int: bool,
    codes_int: bool,
) -> Result<(SampleType, Option<ValueMapping>, Option<Georef>)> {
    let declared = sample_type_from_text(json_text(&meta.source_dtype));
    let mapping = mapping_of(meta)?;
    // The file holds the values; an integer source_dtype describes the codes they came
    // from, through the value mapping when there is one (a uint16 PNG holding metres +
    // 32768: values -5..1580, codes 32763..34348). Keep it only when every value is a code
    // of that type, else take the smallest signed integer type that holds the values
    // themselves (without a mapping), else f32 (which keeps the mapping, for writing the
    // PNG back). A mapping never describes an integer type whose codes it overflows.
    let codes_fit = |t: SampleType, m: ValueMapping| {
        let (a, b) = ((lo - m.offset) / m.scale, (hi - m.offset) / m.scale);
        let (clo, chi) = (a.min(b), a.max(b));
        t.int_range()
            .is_none_or(|(a, b)| codes_int && (lo > hi || (clo >= a && chi <= b)))
    };
    let fits = |t: SampleType| {
        t.int_range()
            .is_none_or(|(a, b)| all_int && (lo > hi || (lo >= a && hi <= b)))
    };
    let (sample_type, mapping) = match mapping {
        _ if !declared.is_integer() => (declared, mapping),
        Some(m) if codes_fit(declared, m) => (declared, mapping),
        None if fits(declared) => (declared, None),
        Some(m) if !m.is_identity() => (SampleType::F32, mapping),
        _ if fits(SampleType::I16) => (SampleType::I16, None),
        _ if fits(SampleType::I32) => (SampleType::I32, None),
        _ => (SampleType::F32, mapping),
    };
    let georef = match meta.georef.clone() {
        Some(g) => Some(g.into()),
        None => match (json_f64(&meta.dx), json_f64(&meta.dy)) {
            (Some(dx), Some(dy)) => georef_from_text(
                json_text(&meta.origin),
                json_text(&meta.units),
                dx,
                dy,
                height,
            ),
            _ => None,
        },
    };
    Ok((sample_type, mapping, georef))
}

/// A raw `.f32` raster read a band of rows at a time by seeking, after one pass over the
/// file for the range of its values (which decides the sample type, as [`read`] does).
pub struct RawSource {
    file: std::io::BufReader<std::fs::File>,
    width: usize,
    height: usize,
    nodata32: Option<f32>,
    sample_type: SampleType,
    mapping: ValueMapping,
    georef: Option<Georef>,
}

impl RawSource {
    /// Open `path`, its sidecar `json` already read. The raster may exceed
    /// `opts.max_samples()`: only bands are held.
    pub fn open(path: &std::path::Path, json: &[u8]) -> Result<RawSource> {
        use std::io::Read;
        expect_json_object(json, "raw sidecar json")?;
        let meta: RawJsonIn = serde_json::from_slice(json)
            .map_err(|e| Error::corrupt(format!("raw sidecar json: {e}")))?;
        let w = json_usize(&meta.width, "width")?;
        let h = json_usize(&meta.height, "height")?;
        let (width, height) = (w as usize, h as usize);
        let n = check_size(w, h, u64::MAX)?;
        let ctx = path.display().to_string();
        let file = std::fs::File::open(path).map_err(|e| Error::io(&ctx, e))?;
        let len = file.metadata().map_err(|e| Error::io(&ctx, e))?.len();
        if len != n as u64 * 4 {
            return Err(Error::corrupt(format!(
                "raw f32 data has {len} bytes, but {width}x{height} samples need {}",
                n as u64 * 4
            )));
        }
        let nodata32 = meta.nodata.map(|v| v.0 as f32);
        if nodata32.is_some_and(f32::is_nan) {
            return Err(Error::corrupt("raw sidecar json: nodata is NaN"));
        }
        let mapping = mapping_of(&meta)?;
        let (mut lo, mut hi, mut all_int) = (f64::INFINITY, f64::NEG_INFINITY, true);
        let mut codes_int = true;
        let mut rd = std::io::BufReader::with_capacity(1 << 20, file);
        // Whole rows at a time (the file's length was checked, so they are all there).
        let mut buf = vec![0u8; width * 4];
        for y in 0..height {
            rd.read_exact(&mut buf).map_err(|e| Error::io(&ctx, e))?;
            for (x, c) in buf.chunks_exact(4).enumerate() {
                let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                if nodata32.is_some_and(|nd| v == nd) || v.is_nan() {
                    continue;
                }
                if v.is_infinite() {
                    return Err(Error::corrupt(format!(
                        "raw f32 sample {} (row {y}, col {x}) is infinite",
                        y * width + x
                    )));
                }
                let d = v as f64;
                lo = lo.min(d);
                hi = hi.max(d);
                all_int &= d.fract() == 0.0;
                codes_int &= mapping.is_none_or(|m| is_code(m, d));
            }
        }
        let (sample_type, mapping, georef) = band_meta(&meta, height, lo, hi, all_int, codes_int)?;
        Ok(RawSource {
            file: rd,
            width,
            height,
            nodata32,
            sample_type,
            mapping: mapping.unwrap_or_default(),
            georef,
        })
    }
}

impl crate::model::RowSource for RawSource {
    fn width(&self) -> usize {
        self.width
    }
    fn height(&self) -> usize {
        self.height
    }
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        use std::io::{Read, Seek, SeekFrom};
        if y0 + rows > self.height {
            return Err(Error::invalid("band outside the raster"));
        }
        let io = |e| Error::io("reading the raw f32 file", e);
        self.file
            .seek(SeekFrom::Start((y0 * self.width * 4) as u64))
            .map_err(io)?;
        let mut buf = vec![0u8; rows * self.width * 4];
        self.file.read_exact(&mut buf).map_err(io)?;
        let data: Vec<f64> = buf
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .collect();
        let mut r = Raster::from_values(
            self.width,
            rows,
            data,
            self.nodata32.map(|v| v as f64),
            self.sample_type,
        )?;
        r.mapping = self.mapping;
        r.georef = self.georef.as_ref().map(|g| g.window(0, y0));
        Ok(r)
    }
}

/// Write a raster as raw little-endian f32 bytes plus a json sidecar.
///
/// Valid samples are cast to f32 (lossy for f64 and large i32 values); invalid samples hold
/// the nodata value (as f32) or NaN when none is declared.
pub fn write(r: &Raster) -> Result<(Vec<u8>, Vec<u8>)> {
    let nodata32 = r.nodata.map(|v| v as f32);
    let fill = nodata32.unwrap_or(f32::NAN);
    let mut out = Vec::with_capacity(r.len() * 4);
    for (i, &v) in r.data.iter().enumerate() {
        let s = if r.is_valid(i) {
            let s = valid_f32(r, i)?;
            if nodata32 == Some(s) {
                return Err(Error::invalid(format!(
                    "sample {i} (row {}, col {}) = {v} equals the nodata value once rounded to float32",
                    i / r.width,
                    i % r.width
                )));
            }
            s
        } else {
            fill
        };
        out.extend_from_slice(&s.to_le_bytes());
    }
    let meta = RawJsonOut {
        width: r.width,
        height: r.height,
        source_dtype: r.sample_type.name(),
        nodata: r.nodata.map(ExactF64),
        dx: r.georef.as_ref().map(|g| ExactF64(g.pixel_size[0])),
        dy: r.georef.as_ref().map(|g| ExactF64(g.pixel_size[1])),
        row_order: if r.georef.as_ref().is_some_and(|g| g.pixel_size[1] < 0.0) {
            "row 0 is the southern (bottom) edge; row-major, little-endian float32"
        } else {
            "row 0 is the northern (top) edge; row-major, little-endian float32"
        },
        georef: r.georef.as_ref().map(GeorefJson::from),
        value_mapping: (!r.mapping.is_identity()).then_some(MappingJson {
            scale: ExactF64(r.mapping.scale),
            offset: ExactF64(r.mapping.offset),
        }),
    };
    let mut json = serde_json::to_vec_pretty(&meta)
        .map_err(|e| Error::invalid(format!("cannot encode raw sidecar json: {e}")))?;
    json.push(b'\n');
    Ok((out, json))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::GeoKeys;
    use crate::testutil::*;

    fn opts() -> ReadOptions {
        ReadOptions::default()
    }

    #[test]
    fn dtype_text() {
        assert_eq!(
            sample_type_from_text("int16 (big-endian, SRTM .hgt)"),
            SampleType::I16
        );
        assert_eq!(sample_type_from_text("uint16"), SampleType::U16);
        assert_eq!(
            sample_type_from_text("uint16 PNG (grey 16-bit); elevation = value - 32768"),
            SampleType::U16
        );
        assert_eq!(
            sample_type_from_text("int32 (R integer matrix, class 'bathy')"),
            SampleType::I32
        );
        assert_eq!(
            sample_type_from_text("float64 LAS point coordinates gridded to float32"),
            SampleType::F32
        );
        assert_eq!(
            sample_type_from_text("ESRI ASCII grid (text decimal)"),
            SampleType::F32
        );
        assert_eq!(
            sample_type_from_text("Terrain-RGB PNG (RGBA 8-bit)"),
            SampleType::F32
        );
        for t in [
            SampleType::U8,
            SampleType::I16,
            SampleType::U16,
            SampleType::I32,
            SampleType::F32,
        ] {
            assert_eq!(sample_type_from_text(t.name()), t);
        }
        assert_eq!(sample_type_from_text("f64"), SampleType::F32);
    }

    #[test]
    fn origin_text() {
        // (origin text, units text, pixel size, height, the origin, raster type and EPSG code
        // read from them)
        type Case<'a> = (
            &'a str,
            &'a str,
            f64,
            usize,
            Option<([f64; 2], RasterType, Option<u32>)>,
        );
        let cases: &[Case] = &[
            (
                "cell centre of row 0, col 0 = lat 23, lon -160 (NW corner of the 1x1 degree tile N22W160)",
                "degrees (WGS84 lon/lat); elevation metres (EGM96)",
                1.0 / 1200.0,
                1201,
                Some(([-160.0, 23.0], RasterType::Point, Some(4326))),
            ),
            (
                "upper-left corner x=376313.6554542635, y=3807917.8276283755 (UTM 11N)",
                "metres (UTM zone 11N, WGS84); elevation metres",
                30.0,
                643,
                Some((
                    [376313.6554542635, 3807917.8276283755],
                    RasterType::Area,
                    Some(32611),
                )),
            ),
            (
                "upper-left corner lon -97.4849999999961, lat 32.82166666666536",
                "degrees (WGS84 lon/lat); elevation metres",
                0.0008333333333333,
                359,
                Some((
                    [-97.4849999999961, 32.82166666666536],
                    RasterType::Area,
                    Some(4326),
                )),
            ),
            (
                "lower-left corner x=0.0, y=0.0",
                "metres (local coordinates, origin 0,0)",
                2.0,
                10,
                Some(([0.0, 20.0], RasterType::Area, None)),
            ),
            (
                "upper-left corner x=84808.0, y=447642.0",
                "metres (EPSG:28992 Amersfoort / RD New); elevation metres NAP",
                0.5,
                459,
                Some(([84808.0, 447642.0], RasterType::Area, Some(28992))),
            ),
            (
                "NW corner approx lat 37.179392, lon -122.366765",
                "",
                200.0,
                540,
                None,
            ),
            ("row 0 = first row of the STM file", "", 1.0, 5, None),
        ];
        for &(origin, units, d, height, want) in cases {
            let g = georef_from_text(origin, units, d, d, height);
            let got = g.map(|g| (g.origin, g.raster_type, g.epsg));
            assert_eq!(got, want, "{origin}");
        }
    }

    fn sample_raster() -> Raster {
        let mut r = Raster::from_values(
            3,
            2,
            vec![1.5, -9999.0, 3.25, 0.125, f64::NAN, 7.0],
            Some(-9999.0),
            SampleType::F32,
        )
        .unwrap();
        r.georef = Some(Georef {
            origin: [0.1 + 0.2, 1.0 / 3.0],
            pixel_size: [1.0 / 1200.0, 0.016666666666666666],
            raster_type: RasterType::Point,
            epsg: Some(4326),
            wkt: Some("GEOGCS[\"WGS 84\"]".into()),
            geokeys: Some(GeoKeys {
                directory: vec![1, 1, 0, 1, 1024, 0, 1, 2],
                doubles: vec![6378137.0, 298.257223563, 0.1 + 0.7],
                ascii: "WGS 84|".into(),
            }),
        });
        r.mapping = ValueMapping {
            scale: 0.1,
            offset: -10000.0,
        };
        r
    }

    #[test]
    fn write_read_roundtrip() {
        let r = sample_raster();
        let (f, j) = write(&r).unwrap();
        assert_eq!(f.len(), 24);
        let back = read(&f, &j, &opts()).unwrap();
        assert_same(&r, &back, "raw round trip");
        assert_eq!(back.mapping, r.mapping);
        assert_eq!(back.nodata, Some(-9999.0));
        // No nodata declared: invalid samples become NaN and read back invalid.
        let r2 = Raster::from_values(2, 2, vec![1.0, f64::NAN, 3.0, 4.0], None, SampleType::I16)
            .unwrap();
        let (f, j) = write(&r2).unwrap();
        assert!(f32::from_le_bytes([f[4], f[5], f[6], f[7]]).is_nan());
        let back = read(&f, &j, &opts()).unwrap();
        assert_same(&r2, &back, "raw round trip");
    }

    #[test]
    fn write_rejects_unrepresentable() {
        let r = Raster::from_values(1, 1, vec![1e300], None, SampleType::F64).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
        let r = Raster::from_values(2, 1, vec![-9999.00001, 1.0], Some(-9999.0), SampleType::F64)
            .unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
    }

    #[test]
    fn garbage_and_limits() {
        let r = sample_raster();
        let (f, j) = write(&r).unwrap();
        for cut in 0..f.len() {
            assert!(read(&f[..cut], &j, &opts()).is_err());
        }
        for cut in 0..j.len() {
            let _ = read(&f, &j[..cut], &opts());
        }
        let mut rng = Rng(99);
        for len in [0, 1, 7, 100, 1000] {
            let junk = rng.bytes(len);
            assert!(read(&junk, &junk, &opts()).is_err());
            assert!(read(&f, &junk, &opts()).is_err());
        }
        let big = br#"{"width": 100000000, "height": 100000000, "source_dtype": "f32"}"#;
        assert!(matches!(
            read(&[], big, &opts()),
            Err(Error::LimitExceeded { .. })
        ));
        // An integer source_dtype the values do not fit falls back to a type they fit.
        let u16_json = br#"{"width": 2, "height": 1, "source_dtype": "uint16"}"#;
        let two = |second: f32| [1.0f32, second].map(f32::to_le_bytes).concat();
        for (second, want) in [
            (0.5, SampleType::F32),
            (-3.0, SampleType::I16),
            (1e6, SampleType::I32),
        ] {
            let st = read(&two(second), u16_json, &opts()).unwrap().sample_type;
            assert_eq!(st, want, "second sample {second}");
        }
        let ok = br#"{"width": 2, "height": 1}"#;
        assert!(matches!(
            read(&two(f32::INFINITY), ok, &opts()),
            Err(Error::Corrupt { .. })
        ));
    }

    /// The file holds metres; `source_dtype` and `value_mapping` the codes they came from
    /// (a uint16 PNG of metres + 32768). The type is kept when every value is such a code,
    /// and a mapping never rides on an integer type whose codes it overflows (which left
    /// every lossy method unable to code the raster).
    #[test]
    fn source_dtype_describes_the_codes_through_the_mapping() {
        let vals = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let side = |dtype: &str, offset: f64| {
            format!(
                r#"{{"width": 3, "height": 1, "source_dtype": "{dtype}",
                    "value_mapping": {{"scale": 1.0, "offset": {offset}}}}}"#
            )
        };
        let metres = vals(&[-5.0, 0.0, 1580.0]);
        let r = read(&metres, side("u16", -32768.0).as_bytes(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::U16);
        assert_eq!(r.mapping.offset, -32768.0);
        assert_eq!(r.value_step(), Some(1.0));
        // Codes 32763..34348 overflow i16: f32, the mapping kept for writing a PNG back.
        let r = read(&metres, side("i16", -32768.0).as_bytes(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::F32);
        // Values that are no whole codes of the mapping (a half-step offset): not u16.
        let r = read(&metres, side("u16", -32768.5).as_bytes(), &opts()).unwrap();
        assert!(!r.sample_type.is_integer(), "{:?}", r.sample_type);
        // The streaming reader decides the same.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.f32");
        std::fs::write(&p, &metres).unwrap();
        let src = RawSource::open(&p, side("u16", -32768.0).as_bytes()).unwrap();
        assert_eq!(
            (src.sample_type, src.mapping.offset),
            (SampleType::U16, -32768.0)
        );
    }

    #[test]
    fn corpus_all() {
        let Some(dir) = corpus() else { return };
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| {
                let p = e.unwrap().path();
                (p.extension()? == "f32").then(|| p.file_stem().unwrap().to_string_lossy().into())
            })
            .collect();
        names.sort();
        assert!(!names.is_empty());
        for name in &names {
            let r = load_raw(&dir, name);
            let meta: serde_json::Value =
                serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap())
                    .unwrap();
            assert_eq!(raster_bits(&r), raw_bits(&dir, name), "{name}");
            let frac = meta["stats"]["nodata_fraction"].as_f64().unwrap_or(0.0);
            let invalid = r.len() - r.valid_count();
            assert!(
                ((invalid as f64 / r.len() as f64) - frac).abs() < 1e-5,
                "{name}: {invalid} invalid vs fraction {frac}"
            );
            // write → read is identical
            let (f, j) = write(&r).unwrap();
            let back = read(&f, &j, &opts()).unwrap();
            assert_same(&r, &back, "raw round trip");
            eprintln!(
                "{name}: {:?} nodata {:?} georef {:?}",
                r.sample_type, r.nodata, r.georef
            );
        }
        let k = load_raw(&dir, "srtm3_N22W160_kauai");
        assert_eq!(k.sample_type, SampleType::I16);
        assert_eq!(k.georef.as_ref().unwrap().origin, [-160.0, 23.0]);
        assert_eq!(
            load_raw(&dir, "etopo_aleutians_marmap").sample_type,
            SampleType::I32
        );
        assert_eq!(load_raw(&dir, "scape_crater").sample_type, SampleType::U16);
        assert_eq!(
            load_raw(&dir, "srtm1_N45E013_istria_crop2400").sample_type,
            SampleType::I16
        );
        assert!(load_raw(&dir, "scape_crater").georef.is_none());
    }
}
