//! The flat-regions section: which samples lie in a flat region (a context-coded bitmap,
//! `bitmap`) and each region's value; a decoder labels the regions itself
//! (4-connected, in raster order: `model::flat::label_runs`) and gives every sample of region k
//! value k.

use super::bitmap;
use super::bytes::{ByteReader, PutLe};
use crate::error::Result;
use crate::model::flat::{BLOCK, label_runs};
use crate::model::{SampleType, ValueMapping};

/// Coding 0: the bitmap of valid samples, range coded with neighbour contexts.
const CODING_CONTEXT: u8 = 0;
/// Coding 1: the same bitmap over aligned [`BLOCK`]² blocks (a block is flat or not as a
/// whole), coded for the blocks whose samples are all valid.
const CODING_BLOCKS: u8 = 1;

/// Per block of a `w × h` raster (row-major, `w.div_ceil(BLOCK)` wide) whether all its
/// samples are valid per `mask`.
fn blocks_valid(w: usize, h: usize, mask: Option<&[bool]>) -> Vec<bool> {
    let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
    let mut ok = vec![true; bw * bh];
    if let Some(m) = mask
        && w > 0
    {
        // Row by row, a block's run of a row at a time (no division per sample: this ran
        // 15 instructions a sample, 6 % of a 512² web tile's decode).
        for (y, row) in m.chunks(w).take(h).enumerate() {
            let oks = &mut ok[(y / BLOCK) * bw..][..bw];
            for (o, run) in oks.iter_mut().zip(row.chunks(BLOCK)) {
                if run.contains(&false) {
                    *o = false;
                }
            }
        }
    }
    ok
}

/// Encode the flat regions `values` (per sample its region's value, NaN elsewhere; only
/// valid samples per `mask` may be flat) of a `w`-wide raster with coding 1. The flat
/// samples must be whole aligned [`BLOCK`]² blocks of valid samples (as
/// `model::flat::find` keeps them).
pub fn encode(values: &[f64], w: usize, mask: Option<&[bool]>) -> Vec<u8> {
    let flat: Vec<bool> = values.iter().map(|v| !v.is_nan()).collect();
    let h = flat.len() / w.max(1);
    let bw = w.div_ceil(BLOCK);
    let blocks: Vec<bool> = (0..bw * h.div_ceil(BLOCK))
        .map(|b| flat[(b / bw) * BLOCK * w + (b % bw) * BLOCK])
        .collect();
    debug_assert!(
        (0..flat.len()).all(|i| flat[i] == blocks[(i / w / BLOCK) * bw + (i % w) / BLOCK]),
        "flat samples are whole blocks"
    );
    let valid = blocks_valid(w, h, mask);
    header(&flat, values, w, CODING_BLOCKS, |out| {
        out.extend_from_slice(&bitmap::encode(&blocks, bw, |b| valid[b]));
    })
}

#[cfg(test)]
/// Encode with coding 0 (the bitmap of every valid sample): what files before coding 1
/// hold; kept for the tests of that coding.
pub fn encode_samples(values: &[f64], w: usize, mask: Option<&[bool]>) -> Vec<u8> {
    let flat: Vec<bool> = values.iter().map(|v| !v.is_nan()).collect();
    header(&flat, values, w, CODING_CONTEXT, |out| {
        out.extend_from_slice(&bitmap::encode(&flat, w, |i| mask.is_none_or(|m| m[i])));
    })
}

/// The section's fields before the bitmap, then the bitmap `stream` writes.
fn header(
    flat: &[bool],
    values: &[f64],
    w: usize,
    coding: u8,
    stream: impl FnOnce(&mut Vec<u8>),
) -> Vec<u8> {
    let (runs, count) = label_runs(flat, w);
    let mut region_values = vec![0f64; count as usize];
    for &(start, _, l) in &runs {
        region_values[l as usize] = values[start as usize];
    }
    let mut out = Vec::new();
    out.put_u8(coding);
    out.put_u8(0);
    out.put_u8(0);
    out.put_u8(0);
    out.put_u32(count);
    out.put_u64(crate::model::count_true(flat) as u64);
    out.put_u64(flat.len() as u64);
    for v in region_values {
        out.put_f64(v);
    }
    stream(&mut out);
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
    /// The raster's samples (for [`Flat::dense`]).
    #[cfg(test)]
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

    /// Per sample its region's value, NaN elsewhere.
    #[cfg(test)]
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
/// `mask`, of sample type `st` under the value mapping `mapping` (each region's value must
/// be a value of it).
pub fn decode(
    payload: &[u8],
    w: usize,
    n: usize,
    mask: Option<&[bool]>,
    (st, mapping): (SampleType, ValueMapping),
) -> Result<Flat> {
    let mut r = ByteReader::new(payload, "flat section");
    let coding = r.u8("coding")?;
    if coding != CODING_CONTEXT && coding != CODING_BLOCKS {
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
    // A region's value is every one of its samples' decoded value, written as stored: it
    // must be a value of the sample type (an i16 file's region cannot hold 2.1e-314).
    for (k, &v) in values.iter().enumerate() {
        st.check_holds(&format!("region {k}'s value"), v, mapping)
            .map_err(|m| r.corrupt(m))?;
    }
    if mask.is_some_and(|m| m.len() != n) {
        return Err(r.corrupt("mask size differs"));
    }
    let stream = r.take(r.remaining(), "bitmap")?;
    let flat = if coding == CODING_CONTEXT {
        bitmap::decode(stream, w, n, |i| mask.is_none_or(|m| m[i]))?
    } else {
        // n = w·h was checked against the limits before this section was read, and the
        // blocks are fewer than the samples.
        let h = n.checked_div(w).unwrap_or(0);
        let bw = w.div_ceil(BLOCK);
        let valid = blocks_valid(w, h, mask);
        let blocks = bitmap::decode(stream, bw, valid.len(), |b| valid[b])?;
        // Each row takes its block row's flags, a block's BLOCK samples at a time.
        let mut flat = vec![false; n];
        for (y, row) in flat.chunks_mut(w.max(1)).enumerate() {
            let brow = &blocks[(y / BLOCK) * bw..(y / BLOCK + 1) * bw];
            for (cells, &b) in row.chunks_mut(BLOCK).zip(brow) {
                cells.fill(b);
            }
        }
        flat
    };
    let seen = crate::model::count_true(&flat) as u64;
    if seen != flat_count {
        return Err(r.corrupt(format!(
            "the bitmap has {seen} flat samples, the header says {flat_count}"
        )));
    }
    let (runs, found) = label_runs(&flat, w);
    if found as usize != count {
        return Err(r.corrupt(format!(
            "the bitmap makes {found} regions, the header says {count}"
        )));
    }
    Ok(Flat {
        runs,
        values,
        #[cfg(test)]
        n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const F64: (SampleType, ValueMapping) = (
        SampleType::F64,
        ValueMapping {
            scale: 1.0,
            offset: 0.0,
        },
    );

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
        let p = encode_samples(&v, w, None);
        assert_eq!(p[0], CODING_CONTEXT);
        let flat = decode(&p, w, w * h, None, F64).unwrap();
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
            assert!(
                decode(&p[..cut], w, w * h, None, F64).is_err(),
                "prefix {cut}"
            );
        }
        // With a mask, nodata samples cost nothing and cannot be flat.
        let mut mask = vec![true; w * h];
        mask[w * h - 1] = false;
        v[w * h - 1] = f64::NAN;
        let p = encode_samples(&v, w, Some(&mask));
        let back = decode(&p, w, w * h, Some(&mask), F64).unwrap().dense();
        for (a, b) in v.iter().zip(&back) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        // The wrong sample count is rejected.
        assert!(decode(&p, w, w * h - 1, None, F64).is_err());
    }

    /// A jagged shore of a sea of 0 and a lake: the flat samples as `model::flat::find`
    /// keeps them (whole aligned blocks) decode exactly from coding 1, whose bitmap is under
    /// half that of coding 0 of the same samples; a nodata sample keeps its block
    /// out of every region and costs no bit.
    #[test]
    fn block_coding_round_trips_and_is_cheaper_than_per_sample() {
        let (w, h) = (203, 157);
        // Per sample: sea left of a jagged shore, a lake at 12.5 in a box.
        let shore = |y: usize| 60 + (y * 7919 % 13) + (y / 9) % 5;
        let mut v = vec![f64::NAN; w * h];
        for y in 0..h {
            for x in 0..w {
                if x < shore(y) {
                    v[y * w + x] = 0.0;
                } else if (120..190).contains(&x) && (30..140).contains(&y) {
                    v[y * w + x] = 12.5;
                }
            }
        }
        let mut mask = vec![true; w * h];
        mask[100 * w + 150] = false;
        // The blocks wholly in one region (and valid), as the encoder keeps them.
        let bw = w.div_ceil(BLOCK);
        let block_of = |i: usize| (i / w / BLOCK) * bw + (i % w) / BLOCK;
        let mut whole = vec![true; bw * h.div_ceil(BLOCK)];
        for i in 0..w * h {
            let first = (block_of(i) / bw) * BLOCK * w + (block_of(i) % bw) * BLOCK;
            if v[i].is_nan() || !mask[i] || v[i] != v[first] {
                whole[block_of(i)] = false;
            }
        }
        let kept: Vec<f64> = (0..w * h)
            .map(|i| if whole[block_of(i)] { v[i] } else { f64::NAN })
            .collect();
        let p = encode(&kept, w, Some(&mask));
        assert_eq!(p[0], CODING_BLOCKS);
        let back = decode(&p, w, w * h, Some(&mask), F64).unwrap().dense();
        for (a, b) in kept.iter().zip(&back) {
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
        }
        // The nodata sample's block and the lake's partial blocks are out; the rest is in.
        assert!(back[100 * w + 150].is_nan() && back[100 * w + 148].is_nan());
        assert!(back[40 * w + 185].is_nan() && back[40 * w + 121] == 12.5 && back[0] == 0.0);
        // Coding 0 of the same samples, and of the whole regions.
        let samples = encode_samples(&kept, w, Some(&mask));
        let whole_regions = encode_samples(&v, w, Some(&mask));
        assert!(
            2 * (p.len() - 40) < samples.len() - 40 && p.len() < whole_regions.len(),
            "coding 1: {} bytes, coding 0: {} (whole regions {})",
            p.len(),
            samples.len(),
            whole_regions.len()
        );
        for cut in 0..p.len() {
            assert!(
                decode(&p[..cut], w, w * h, Some(&mask), F64).is_err(),
                "prefix {cut}"
            );
        }
    }
}
