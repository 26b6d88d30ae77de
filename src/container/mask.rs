//! The validity-mask section: run lengths of valid/invalid samples, varint + DEFLATE coded
//! (coding 0), or the bitmap context coded (coding 1, `bitmap`); the writer keeps the
//! smaller.

use super::bytes::{ByteReader, PutLe};
use crate::entropy::{self, varint};
use crate::error::Result;

/// Mask coding 0: alternating run lengths (valid first) as LEB128 varints, raw DEFLATE.
const CODING_RUNS_DEFLATE: u8 = 0;

/// Mask coding 1: the invalid bits, context coded (`bitmap`).
const CODING_CONTEXT: u8 = 1;

/// Encode the mask (`true` = valid) of a `w`-wide raster into a mask-section payload: the
/// smaller of the two codings.
pub fn encode(mask: &[bool], w: usize) -> Vec<u8> {
    let runs = encode_runs(mask);
    let invalid: Vec<bool> = mask.iter().map(|&b| !b).collect();
    let mut ctx = Vec::new();
    ctx.put_u8(CODING_CONTEXT);
    ctx.put_u64(invalid.iter().filter(|&&b| b).count() as u64);
    ctx.put_u64(mask.len() as u64);
    ctx.extend_from_slice(&super::bitmap::encode(&invalid, w, |_| true));
    if ctx.len() < runs.len() { ctx } else { runs }
}

/// Coding 0 of a mask.
fn encode_runs(mask: &[bool]) -> Vec<u8> {
    let mut runs = Vec::new();
    let mut current = true;
    let mut run: u64 = 0;
    let mut invalid: u64 = 0;
    for &b in mask {
        if !b {
            invalid += 1;
        }
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
    out.put_u8(CODING_RUNS_DEFLATE);
    out.put_u64(invalid);
    out.extend_from_slice(&entropy::deflate(&runs));
    out
}

/// Decode a mask-section payload for a `w`-wide raster of `n` samples.
pub fn decode(payload: &[u8], w: usize, n: usize) -> Result<Vec<bool>> {
    let mut r = ByteReader::new(payload, "mask section");
    let coding = r.u8("coding")?;
    if coding != CODING_RUNS_DEFLATE && coding != CODING_CONTEXT {
        return Err(r.corrupt(format!("mask coding {coding} is not defined")));
    }
    let invalid = r.u64("invalid count")?;
    if invalid > n as u64 {
        return Err(r.corrupt(format!("invalid count {invalid} exceeds {n} samples")));
    }
    if coding == CODING_CONTEXT {
        let samples = r.u64("sample count")?;
        if samples != n as u64 {
            return Err(r.corrupt(format!("holds {samples} samples, the raster has {n}")));
        }
        let bits = super::bitmap::decode(r.take(r.remaining(), "bitmap")?, w.max(1), n, |_| true)?;
        let seen = bits.iter().filter(|&&b| b).count() as u64;
        if seen != invalid {
            return Err(r.corrupt(format!(
                "the bitmap has {seen} invalid samples, the header says {invalid}"
            )));
        }
        return Ok(bits.into_iter().map(|b| !b).collect());
    }
    let rest = r.take(r.remaining(), "runs")?;
    // n + 1 runs at most, 10 bytes each at most.
    let runs = entropy::inflate(rest, (n + 1).saturating_mul(10), "mask section")?;
    let mut vr = varint::VarintReader::new(&runs, "mask section runs");
    let mut mask = Vec::with_capacity(n);
    let mut current = true;
    let mut seen_invalid: u64 = 0;
    let mut k = 0usize;
    while mask.len() < n {
        let run = vr.u64()?;
        if run > (n - mask.len()) as u64 {
            return Err(r.corrupt("runs add up to more samples than the raster has"));
        }
        if run == 0 && k > 0 {
            return Err(r.corrupt("empty run after the first"));
        }
        k += 1;
        mask.extend(std::iter::repeat_n(current, run as usize));
        if !current {
            seen_invalid += run;
        }
        current = !current;
    }
    vr.finish()?;
    if seen_invalid != invalid {
        return Err(r.corrupt(format!(
            "runs give {seen_invalid} invalid samples, the header says {invalid}"
        )));
    }
    Ok(mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(256))]
        #[test]
        fn masks_round_trip(mask in proptest::collection::vec(proptest::bool::weighted(0.8), 1..3000)) {
            let enc = encode(&mask, 7);
            prop_assert_eq!(decode(&enc, 7, mask.len()).unwrap(), mask.clone());
            let runs = encode_runs(&mask);
            prop_assert_eq!(decode(&runs, 7, mask.len()).unwrap(), mask.clone());
            // Wrong sample counts are rejected.
            prop_assert!(decode(&enc, 7, mask.len() + 1).is_err());
            if mask.len() > 1 {
                prop_assert!(decode(&enc, 7, mask.len() - 1).is_err());
            }
        }
    }

    #[test]
    fn all_invalid_and_all_valid() {
        for mask in [vec![false; 100], vec![true; 100], vec![false], vec![true]] {
            assert_eq!(decode(&encode(&mask, 10), 10, mask.len()).unwrap(), mask);
        }
    }
}
