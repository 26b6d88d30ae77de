//! The JSON forms the sidecars share: georef, GeoKeys and exact floats, with their conversions.
//!
//! The georef object (in the raw `.f32` sidecar, the PNG sidecar and the EXR `vtz_georef`
//! attribute) is `{"origin": [x, y], "pixel_size": [dx, dy], "raster_type": "area"|"point",
//! "epsg": n|null, "wkt": s|null, "geokeys": {"directory": [..], "doubles": [..], "ascii":
//! s}|null}`. A float that serde_json would not read back bit for bit from a JSON number
//! (rare: some 17-digit values; also NaN and infinities) is written as a string holding its
//! shortest form ([`ExactF64`]), so the georef round-trips exactly.

use crate::error::{Error, Result};
use crate::model::{GeoKeys, Georef, RasterType};
use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// An `f64` that survives a JSON round trip bit for bit.
///
/// serde_json (without its `float_roundtrip` feature) may parse long decimals one ulp off, so
/// a value is written as a JSON number only when serde_json reads that number back exactly;
/// otherwise (and for NaN/±inf) it is written as a string in Rust's shortest round-trip form,
/// which `str::parse` reads back exactly. Reading accepts either form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ExactF64(pub f64);

fn json_number_roundtrips(v: f64) -> bool {
    serde_json::to_string(&v)
        .ok()
        .and_then(|t| serde_json::from_str::<f64>(&t).ok())
        .is_some_and(|b| b.to_bits() == v.to_bits())
}

impl Serialize for ExactF64 {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        let v = self.0;
        if v.is_finite() && json_number_roundtrips(v) {
            s.serialize_f64(v)
        } else {
            s.serialize_str(&format!("{v:?}"))
        }
    }
}

impl<'de> Deserialize<'de> for ExactF64 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = ExactF64;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or a string holding a number")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<ExactF64, E> {
                Ok(ExactF64(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<ExactF64, E> {
                Ok(ExactF64(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<ExactF64, E> {
                Ok(ExactF64(v as f64))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> std::result::Result<ExactF64, E> {
                v.trim()
                    .parse::<f64>()
                    .map(ExactF64)
                    .map_err(|_| E::custom(format!("'{v}' is not a number")))
            }
        }
        d.deserialize_any(V)
    }
}

/// Refuse json that is not an object before handing it to serde (which would also accept a
/// bare array for a struct).
pub(crate) fn expect_json_object(bytes: &[u8], what: &str) -> Result<()> {
    let first = bytes.iter().copied().find(|b| !b.is_ascii_whitespace());
    if first != Some(b'{') {
        return Err(Error::corrupt(format!("{what}: not a JSON object")));
    }
    Ok(())
}

/// JSON form of [`RasterType`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RasterTypeJson {
    Area,
    Point,
}

/// JSON form of [`GeoKeys`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct GeoKeysJson {
    pub directory: Vec<u16>,
    pub doubles: Vec<ExactF64>,
    pub ascii: String,
}

/// JSON form of [`Georef`], shared by the raw and PNG sidecars and the EXR attribute.
/// Converts both ways exactly:
/// `{"origin": [x, y], "pixel_size": [dx, dy], "raster_type": "area"|"point",
/// "epsg": n|null, "wkt": s|null, "geokeys": {"directory": [...], "doubles": [...],
/// "ascii": s}|null}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct GeorefJson {
    pub origin: [ExactF64; 2],
    pub pixel_size: [ExactF64; 2],
    pub raster_type: RasterTypeJson,
    #[serde(default)]
    pub epsg: Option<u32>,
    #[serde(default)]
    pub wkt: Option<String>,
    #[serde(default)]
    pub geokeys: Option<GeoKeysJson>,
}

impl From<&Georef> for GeorefJson {
    fn from(g: &Georef) -> Self {
        GeorefJson {
            origin: [ExactF64(g.origin[0]), ExactF64(g.origin[1])],
            pixel_size: [ExactF64(g.pixel_size[0]), ExactF64(g.pixel_size[1])],
            raster_type: match g.raster_type {
                RasterType::Area => RasterTypeJson::Area,
                RasterType::Point => RasterTypeJson::Point,
            },
            epsg: g.epsg,
            wkt: g.wkt.clone(),
            geokeys: g.geokeys.as_ref().map(|k| GeoKeysJson {
                directory: k.directory.clone(),
                doubles: k.doubles.iter().map(|&d| ExactF64(d)).collect(),
                ascii: k.ascii.clone(),
            }),
        }
    }
}

impl From<GeorefJson> for Georef {
    fn from(g: GeorefJson) -> Self {
        Georef {
            origin: [g.origin[0].0, g.origin[1].0],
            pixel_size: [g.pixel_size[0].0, g.pixel_size[1].0],
            raster_type: match g.raster_type {
                RasterTypeJson::Area => RasterType::Area,
                RasterTypeJson::Point => RasterType::Point,
            },
            epsg: g.epsg,
            wkt: g.wkt,
            geokeys: g.geokeys.map(|k| GeoKeys {
                directory: k.directory,
                doubles: k.doubles.into_iter().map(|d| d.0).collect(),
                ascii: k.ascii,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::Rng;

    #[test]
    fn exact_f64_json() {
        let mut rng = Rng(0x1234_5678_9abc_def1);
        let mut vals: Vec<f64> = (0..20000).map(|_| f64::from_bits(rng.next())).collect();
        vals.extend([
            0.0,
            -0.0,
            0.016666666666666666,
            1.0 / 3600.0,
            -3.3999999521443642e38,
            f64::NAN,
            f64::INFINITY,
            f64::MIN_POSITIVE,
            5e-324,
        ]);
        for v in vals {
            let s = serde_json::to_string(&ExactF64(v)).unwrap();
            let back: ExactF64 = serde_json::from_str(&s).unwrap();
            if v.is_nan() {
                assert!(back.0.is_nan());
            } else {
                assert_eq!(back.0.to_bits(), v.to_bits(), "{v:?} via {s}");
            }
        }
    }
}
