//! The `.vtz` file header: raster size, sample type, value mapping, nodata, range, georef.

use super::bytes::{ByteReader, PutLe};
use crate::error::{Error, Result};
use crate::model::{GeoKeys, Georef, RasterType, SampleType, ValueMapping};

/// Largest header body a decoder accepts (the spec's limit).
pub const MAX_HEADER_LEN: u32 = 1 << 20;

const HF_NODATA: u8 = 1;
const HF_GEOREF: u8 = 2;
const HF_RANGE: u8 = 4;
const HF_KNOWN: u8 = HF_NODATA | HF_GEOREF | HF_RANGE;

/// What every section of a file shares: the raster's shape and meaning.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Raster width in samples.
    pub width: u32,
    /// Raster height in samples.
    pub height: u32,
    /// The source's sample type.
    pub sample_type: SampleType,
    /// Index (in the section directory) of the section that `decode` uses by default.
    pub primary: u16,
    /// Code ↔ value mapping.
    pub mapping: ValueMapping,
    /// The declared nodata value.
    pub nodata: Option<f64>,
    /// (min, max) over the source's valid samples; `None` when it has no valid sample.
    pub range: Option<(f64, f64)>,
    /// Georeferencing, when present.
    pub georef: Option<Georef>,
}

impl Header {
    /// The header describing raster `r` (its size, sample type, mapping, nodata, valid
    /// range and georef); `primary` is 0.
    pub fn of(r: &crate::model::Raster) -> Result<Header> {
        let w = u32::try_from(r.width).map_err(|_| Error::limit("raster wider than 2^32"))?;
        let h = u32::try_from(r.height).map_err(|_| Error::limit("raster taller than 2^32"))?;
        if w > i32::MAX as u32 || h > i32::MAX as u32 {
            return Err(Error::limit("raster dimension over 2^31 - 1"));
        }
        // A decoder rejects a range that is no pair of sample values (spec/FORMAT.md). The
        // samples of a raster read from a file are values of its type; one built with other
        // values (an f32 raster of f64 numbers) decodes to its type's values, and so does
        // its range (rounding is monotone: min ≤ max stays).
        let range = r.valid_range().map(|(lo, hi)| {
            let near = |v| r.sample_type.nearest_value(v, r.mapping);
            (near(lo), near(hi))
        });
        Ok(Header {
            width: w,
            height: h,
            sample_type: r.sample_type,
            primary: 0,
            mapping: r.mapping,
            nodata: r.nodata,
            range,
            georef: r.georef.clone(),
        })
    }

    /// Samples (width × height).
    pub fn samples(&self) -> u64 {
        self.width as u64 * self.height as u64
    }

    /// Serialize the header body (spec/FORMAT.md, "Header body").
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        b.put_u32(self.width);
        b.put_u32(self.height);
        b.put_u8(self.sample_type.code());
        let mut flags = 0;
        if self.nodata.is_some() {
            flags |= HF_NODATA;
        }
        if self.georef.is_some() {
            flags |= HF_GEOREF;
        }
        if self.range.is_some() {
            flags |= HF_RANGE;
        }
        b.put_u8(flags);
        b.put_u16(self.primary);
        b.put_f64(self.mapping.scale);
        b.put_f64(self.mapping.offset);
        if let Some(nd) = self.nodata {
            b.put_f64(nd);
        }
        if let Some((lo, hi)) = self.range {
            b.put_f64(lo);
            b.put_f64(hi);
        }
        if let Some(g) = &self.georef {
            b.put_u8(match g.raster_type {
                RasterType::Area => 1,
                RasterType::Point => 2,
            });
            b.put_f64(g.origin[0]);
            b.put_f64(g.origin[1]);
            b.put_f64(g.pixel_size[0]);
            b.put_f64(g.pixel_size[1]);
            b.put_u32(g.epsg.unwrap_or(0));
            let wkt = g.wkt.as_deref().unwrap_or("");
            b.put_u32(wkt.len() as u32);
            b.extend_from_slice(wkt.as_bytes());
            match &g.geokeys {
                None => b.put_u8(0),
                Some(k) => {
                    b.put_u8(1);
                    b.put_u32(k.directory.len() as u32);
                    for &s in &k.directory {
                        b.put_u16(s);
                    }
                    b.put_u32(k.doubles.len() as u32);
                    for &d in &k.doubles {
                        b.put_f64(d);
                    }
                    b.put_u32(k.ascii.len() as u32);
                    b.extend_from_slice(k.ascii.as_bytes());
                }
            }
        }
        b
    }

    /// Parse and validate a header body; every out-of-range field is rejected.
    pub fn from_bytes(body: &[u8]) -> Result<Header> {
        let mut r = ByteReader::new(body, "header");
        let h = Header::read_fields(&mut r)?;
        r.finish()?;
        Ok(h)
    }

    /// Parse the version-1 header fields from the front of `r` (a version-2 header body
    /// continues with the tile fields).
    pub(crate) fn read_fields(r: &mut ByteReader) -> Result<Header> {
        let width = r.u32("width")?;
        let height = r.u32("height")?;
        if width == 0 || height == 0 || width > i32::MAX as u32 || height > i32::MAX as u32 {
            return Err(r.corrupt(format!("raster size {width}x{height} out of range")));
        }
        let st = r.u8("sample type")?;
        let sample_type = SampleType::from_code(st)
            .ok_or_else(|| r.corrupt(format!("sample type {st} is not defined")))?;
        let flags = r.u8("flags")?;
        if flags & !HF_KNOWN != 0 {
            return Err(Error::unsupported(format!(
                "header: unknown header flags 0x{:02x}",
                flags & !HF_KNOWN
            )));
        }
        let primary = r.u16("primary section")?;
        let scale = r.finite_f64("value scale")?;
        let offset = r.finite_f64("value offset")?;
        if scale == 0.0 {
            return Err(r.corrupt("value scale is zero"));
        }
        let nodata = if flags & HF_NODATA != 0 {
            let v = r.f64("nodata")?;
            if v.is_nan() {
                return Err(r.corrupt("nodata is NaN"));
            }
            Some(v)
        } else {
            None
        };
        let range = if flags & HF_RANGE != 0 {
            let lo = r.finite_f64("minimum")?;
            let hi = r.finite_f64("maximum")?;
            if lo > hi {
                return Err(r.corrupt("minimum is above maximum"));
            }
            // The range is of sample values: each end a value of the sample type.
            for (what, v) in [("minimum", lo), ("maximum", hi)] {
                sample_type
                    .check_holds(what, v, ValueMapping { scale, offset })
                    .map_err(|m| r.corrupt(m))?;
            }
            Some((lo, hi))
        } else {
            None
        };
        let georef = if flags & HF_GEOREF != 0 {
            let rt = r.u8("raster type")?;
            let raster_type = match rt {
                1 => RasterType::Area,
                2 => RasterType::Point,
                _ => return Err(r.corrupt(format!("raster type {rt} is not defined"))),
            };
            let ox = r.finite_f64("origin x")?;
            let oy = r.finite_f64("origin y")?;
            let px = r.finite_f64("pixel width")?;
            let py = r.finite_f64("pixel height")?;
            let epsg = r.u32("epsg")?;
            let wkt_len = r.count(1, "wkt length")?;
            let wkt = std::str::from_utf8(r.take(wkt_len, "wkt")?)
                .map_err(|_| r.corrupt("wkt is not UTF-8"))?
                .to_string();
            let gk = r.u8("geokeys present")?;
            let geokeys = match gk {
                0 => None,
                1 => {
                    let n = r.count(2, "geokey directory length")?;
                    let mut directory = Vec::with_capacity(n);
                    for _ in 0..n {
                        directory.push(r.u16("geokey directory")?);
                    }
                    let n = r.count(8, "geodouble count")?;
                    let mut doubles = Vec::with_capacity(n);
                    for _ in 0..n {
                        doubles.push(r.f64("geodouble")?);
                    }
                    let n = r.count(1, "geoascii length")?;
                    let ascii = std::str::from_utf8(r.take(n, "geoascii")?)
                        .map_err(|_| r.corrupt("geoascii is not UTF-8"))?
                        .to_string();
                    Some(GeoKeys {
                        directory,
                        doubles,
                        ascii,
                    })
                }
                _ => return Err(r.corrupt(format!("geokeys flag {gk} is not 0 or 1"))),
            };
            Some(Georef {
                origin: [ox, oy],
                pixel_size: [px, py],
                raster_type,
                epsg: (epsg != 0).then_some(epsg),
                wkt: (!wkt.is_empty()).then_some(wkt),
                geokeys,
            })
        } else {
            None
        };
        Ok(Header {
            width,
            height,
            sample_type,
            primary,
            mapping: ValueMapping { scale, offset },
            nodata,
            range,
            georef,
        })
    }
}
