//! GDAL_NODATA: the nodata tag's text parsed on reading and formatted on writing.

use super::TAG_GDAL_NODATA;
use super::tags::tag_string;
use crate::error::{Error, Result};
use crate::model::SampleType;
use std::io::{Read, Seek};
use tiff::decoder::Decoder;

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
pub(super) fn read_nodata<R: Read + Seek>(
    dec: &mut Decoder<R>,
    st: SampleType,
) -> Result<Option<f64>> {
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

/// GDAL_NODATA text that parses back to exactly `v`.
pub(super) fn format_nodata(v: f64) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::{read, write};

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
}
