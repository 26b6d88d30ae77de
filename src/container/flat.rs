//! The flat-regions section: which samples lie in a flat region (run lengths, like the
//! mask) and each region's value; a decoder labels the regions itself (4-connected, in
//! raster order: `model::flat::label`) and gives every sample of region k value k.

use super::bytes::{ByteReader, PutLe};
use crate::entropy::{self, varint};
use crate::error::Result;
use crate::model::flat::label;

/// Coding 0: alternating run lengths (not flat first) as varints, raw DEFLATE.
const CODING_RUNS: u8 = 0;

/// Encode the flat regions `values` (per sample its region's value, NaN elsewhere) of a
/// `w`-wide raster.
pub fn encode(values: &[f64], w: usize) -> Vec<u8> {
    let flat: Vec<bool> = values.iter().map(|v| !v.is_nan()).collect();
    let (lab, count) = label(&flat, w);
    let mut region_values = vec![0f64; count as usize];
    for (i, &l) in lab.iter().enumerate() {
        if l != 0 {
            region_values[l as usize - 1] = values[i];
        }
    }
    let mut runs = Vec::new();
    let mut current = false;
    let mut run: u64 = 0;
    for &b in &flat {
        if b == current {
            run += 1;
        } else {
            varint::put_u64(&mut runs, run);
            current = b;
            run = 1;
        }
    }
    varint::put_u64(&mut runs, run);
    let mut out = Vec::new();
    out.put_u8(CODING_RUNS);
    out.put_u8(0);
    out.put_u8(0);
    out.put_u8(0);
    out.put_u32(count);
    out.put_u64(flat.iter().filter(|&&b| b).count() as u64);
    for v in region_values {
        out.put_f64(v);
    }
    out.extend_from_slice(&entropy::deflate(&runs));
    out
}

/// Decode a flat-regions payload for a `w`-wide raster of `n` samples whose validity is
/// `mask`: per sample its region's value, NaN elsewhere.
pub fn decode(payload: &[u8], w: usize, n: usize, mask: Option<&[bool]>) -> Result<Vec<f64>> {
    let mut r = ByteReader::new(payload, "flat section");
    let coding = r.u8("coding")?;
    if coding != CODING_RUNS {
        return Err(r.corrupt(format!("flat coding {coding} is not defined")));
    }
    for _ in 0..3 {
        if r.u8("reserved")? != 0 {
            return Err(r.corrupt("reserved field is not zero"));
        }
    }
    let count = r.u32("region count")? as usize;
    let flat_count = r.u64("flat count")?;
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
    let rest = r.take(r.remaining(), "runs")?;
    let runs = entropy::inflate(rest, (n + 1).saturating_mul(10), "flat section")?;
    let mut vr = varint::VarintReader::new(&runs, "flat section runs");
    let mut flat = Vec::with_capacity(n);
    let mut current = false;
    let mut k = 0usize;
    while flat.len() < n {
        let run = vr.u64()?;
        if run > (n - flat.len()) as u64 {
            return Err(r.corrupt("runs add up to more samples than the raster has"));
        }
        if run == 0 && k > 0 {
            return Err(r.corrupt("empty run after the first"));
        }
        k += 1;
        flat.extend(std::iter::repeat_n(current, run as usize));
        current = !current;
    }
    vr.finish()?;
    let seen = flat.iter().filter(|&&b| b).count() as u64;
    if seen != flat_count {
        return Err(r.corrupt(format!(
            "runs give {seen} flat samples, the header says {flat_count}"
        )));
    }
    if let Some(m) = mask {
        if flat.iter().zip(m).any(|(&f, &v)| f && !v) {
            return Err(r.corrupt("a flat sample is nodata"));
        }
    }
    let (lab, found) = label(&flat, w);
    if found as usize != count {
        return Err(r.corrupt(format!(
            "the runs make {found} regions, the header says {count}"
        )));
    }
    Ok(lab
        .iter()
        .map(|&l| if l == 0 { f64::NAN } else { values[l as usize - 1] })
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
        let p = encode(&v, w);
        let back = decode(&p, w, w * h, None).unwrap();
        for (a, b) in v.iter().zip(&back) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        for cut in 0..p.len() {
            assert!(decode(&p[..cut], w, w * h, None).is_err(), "prefix {cut}");
        }
        // A flat sample over nodata is corrupt.
        let mut mask = vec![true; w * h];
        mask[0] = false;
        assert!(decode(&p, w, w * h, Some(&mask)).is_err());
    }
}
