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

/// Decoded flat regions: runs of flat samples along rows, each with its region's value. It
/// takes memory in proportion to the regions' outlines, not their area (a decoder holds it
/// beside the whole raster).
#[derive(Clone, Debug, Default)]
pub struct Flat {
    /// (first sample index, length, region), sorted by index; a run never crosses a row.
    runs: Vec<(u64, u32, u32)>,
    values: Vec<f64>,
    n: usize,
}

impl Flat {
    /// The value of sample `i` when it is flat.
    pub fn value_at(&self, i: usize) -> Option<f64> {
        let k = self.runs.partition_point(|r| r.0 <= i as u64);
        let (start, len, region) = *self.runs.get(k.checked_sub(1)?)?;
        (i as u64 - start < len as u64).then(|| self.values[region as usize])
    }

    /// Every run as (first sample index, length, value), in index order.
    pub fn runs(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        self.runs
            .iter()
            .map(|&(s, l, r)| (s as usize, l as usize, self.values[r as usize]))
    }

    /// Per sample its region's value, NaN elsewhere (for a method that reads the values).
    pub fn dense(&self) -> Vec<f64> {
        let mut v = vec![f64::NAN; self.n];
        for (s, l, x) in self.runs() {
            v[s..s + l].fill(x);
        }
        v
    }

    /// Write the flat values over `data`, the window `(x0, y0, ww, wh)` of a `w`-wide raster.
    pub fn overwrite(
        &self,
        data: &mut [f64],
        w: usize,
        (x0, y0, ww, wh): (usize, usize, usize, usize),
    ) {
        let first = self.runs.partition_point(|r| r.0 < (y0 * w) as u64);
        for &(s, l, r) in &self.runs[first..] {
            let (y, x) = (s as usize / w, s as usize % w);
            if y >= y0 + wh {
                break;
            }
            let (a, b) = (x.max(x0), (x + l as usize).min(x0 + ww));
            if a < b {
                let row = (y - y0) * ww;
                data[row + a - x0..row + b - x0].fill(self.values[r as usize]);
            }
        }
    }
}

/// Decode a flat-regions payload for a `w`-wide raster of `n` samples whose validity is
/// `mask`.
pub fn decode(payload: &[u8], w: usize, n: usize, mask: Option<&[bool]>) -> Result<Flat> {
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
    let mut runs = Vec::new();
    for (y, row) in lab.chunks(w.max(1)).enumerate() {
        let mut x = 0;
        while x < row.len() {
            let l = row[x];
            let from = x;
            while x < row.len() && row[x] == l {
                x += 1;
            }
            if l != 0 {
                runs.push(((y * w + from) as u64, (x - from) as u32, l - 1));
            }
        }
    }
    Ok(Flat { runs, values, n })
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
        let flat = decode(&p, w, w * h, None).unwrap();
        let back = flat.dense();
        for (i, (a, b)) in v.iter().zip(&back).enumerate() {
            assert!(a == b || (a.is_nan() && b.is_nan()));
            assert_eq!(
                flat.value_at(i).map(f64::to_bits),
                (!a.is_nan()).then(|| a.to_bits())
            );
        }
        // A window's overwrite writes exactly the window's flat samples.
        let (x0, y0, ww, wh) = (3, 2, 12, 5);
        let mut win = vec![-1.0; ww * wh];
        flat.overwrite(&mut win, w, (x0, y0, ww, wh));
        for y in 0..wh {
            for x in 0..ww {
                let want = back[(y0 + y) * w + x0 + x];
                let got = win[y * ww + x];
                assert!(if want.is_nan() {
                    got == -1.0
                } else {
                    got == want
                });
            }
        }
        for cut in 0..p.len() {
            assert!(decode(&p[..cut], w, w * h, None).is_err(), "prefix {cut}");
        }
        // With a mask, nodata samples cost nothing and cannot be flat.
        let mut mask = vec![true; w * h];
        mask[w * h - 1] = false;
        v[w * h - 1] = f64::NAN;
        let p = encode(&v, w, Some(&mask));
        let back = decode(&p, w, w * h, Some(&mask)).unwrap().dense();
        for (a, b) in v.iter().zip(&back) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        // The wrong sample count is rejected.
        assert!(decode(&p, w, w * h - 1, None).is_err());
    }
}
