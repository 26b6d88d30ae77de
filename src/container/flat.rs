//! The flat-regions section: which samples lie in a flat region (a context-coded bitmap,
//! `bitmap`) and each region's value; a decoder labels the regions itself
//! (4-connected, in raster order: `model::flat::label`) and gives every sample of region k
//! value k.

use super::bitmap;
use super::bytes::{ByteReader, PutLe};
use crate::error::Result;
use crate::model::flat::label;

/// Coding 0: the bitmap of valid samples, range coded with neighbour contexts.
const CODING_CONTEXT: u8 = 0;

/// Encode the flat regions `values` (per sample its region's value, NaN elsewhere; only
/// valid samples per `mask` may be flat) of a `w`-wide raster.
pub fn encode(values: &[f64], w: usize, mask: Option<&[bool]>) -> Vec<u8> {
    let flat: Vec<bool> = values.iter().map(|v| !v.is_nan()).collect();
    let (lab, count) = label(&flat, w);
    let mut region_values = vec![0f64; count as usize];
    for (i, &l) in lab.iter().enumerate() {
        if l != 0 {
            region_values[l as usize - 1] = values[i];
        }
    }
    let mut out = Vec::new();
    out.put_u8(CODING_CONTEXT);
    out.put_u8(0);
    out.put_u8(0);
    out.put_u8(0);
    out.put_u32(count);
    out.put_u64(flat.iter().filter(|&&b| b).count() as u64);
    out.put_u64(flat.len() as u64);
    for v in region_values {
        out.put_f64(v);
    }
    out.extend_from_slice(&bitmap::encode(&flat, w, |i| mask.is_none_or(|m| m[i])));
    out
}

/// Decode a flat-regions payload for a `w`-wide raster of `n` samples whose validity is
/// `mask`: per sample its region's value, NaN elsewhere.
pub fn decode(payload: &[u8], w: usize, n: usize, mask: Option<&[bool]>) -> Result<Vec<f64>> {
    let mut r = ByteReader::new(payload, "flat section");
    let coding = r.u8("coding")?;
    if coding != CODING_CONTEXT {
        return Err(r.corrupt(format!("flat coding {coding} is not defined")));
    }
    for _ in 0..3 {
        if r.u8("reserved")? != 0 {
            return Err(r.corrupt("reserved field is not zero"));
        }
    }
    let count = r.u32("region count")? as usize;
    let flat_count = r.u64("flat count")?;
    let samples = r.u64("sample count")?;
    if samples != n as u64 {
        return Err(r.corrupt(format!("holds {samples} samples, the raster has {n}")));
    }
    if flat_count > n as u64 || count as u64 > flat_count {
        return Err(r.corrupt(format!(
            "{count} regions of {flat_count} samples do not fit {n} samples"
        )));
    }
    // The values are read from the payload itself, so their count is bounded by its size.
    let raw = r.take(count.saturating_mul(8), "region values")?;
    let values: Vec<f64> = raw
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    if values.iter().any(|v| !v.is_finite()) {
        return Err(r.corrupt("a region value is not finite"));
    }
    if mask.is_some_and(|m| m.len() != n) {
        return Err(r.corrupt("mask size differs"));
    }
    let stream = r.take(r.remaining(), "bitmap")?;
    let flat = bitmap::decode(stream, w, n, |i| mask.is_none_or(|m| m[i]))?;
    let seen = flat.iter().filter(|&&b| b).count() as u64;
    if seen != flat_count {
        return Err(r.corrupt(format!(
            "the bitmap has {seen} flat samples, the header says {flat_count}"
        )));
    }
    let (lab, found) = label(&flat, w);
    if found as usize != count {
        return Err(r.corrupt(format!(
            "the bitmap makes {found} regions, the header says {count}"
        )));
    }
    Ok(lab
        .iter()
        .map(|&l| {
            if l == 0 {
                f64::NAN
            } else {
                values[l as usize - 1]
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_round_trip_and_prefixes_fail() {
        // Two touching-free regions and a hole.
        let (w, h) = (20, 10);
        let mut v = vec![f64::NAN; w * h];
        for y in 0..h {
            for x in 0..w {
                if x < 8 {
                    v[y * w + x] = 0.0;
                } else if x > 9 && !(y == 5 && x == 15) {
                    v[y * w + x] = 12.5;
                }
            }
        }
        let p = encode(&v, w, None);
        let back = decode(&p, w, w * h, None).unwrap();
        for (a, b) in v.iter().zip(&back) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        for cut in 0..p.len() {
            assert!(decode(&p[..cut], w, w * h, None).is_err(), "prefix {cut}");
        }
        // With a mask, nodata samples cost nothing and cannot be flat.
        let mut mask = vec![true; w * h];
        mask[w * h - 1] = false;
        v[w * h - 1] = f64::NAN;
        let p = encode(&v, w, Some(&mask));
        let back = decode(&p, w, w * h, Some(&mask)).unwrap();
        for (a, b) in v.iter().zip(&back) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        // The wrong sample count is rejected.
        assert!(decode(&p, w, w * h - 1, None).is_err());
    }
}
