//! The payload reader: parses a Haar section, decodes its bands and rebuilds the samples.

use super::coding::code_bands;
use super::lattice::{Lattice, Output};
use super::quant::reconstruct;
use super::transform::{Pyramid, max_levels};
use super::{CODING_PYRAMID, MAX_STEP, STEP_UNIT};
use crate::container::Header;
use crate::container::bytes::ByteReader;
use crate::entropy::range::Decoder;
use crate::error::{Error, Result};

fn read_varint(r: &mut ByteReader, field: &str) -> Result<u64> {
    let mut v = 0u64;
    for k in 0..10 {
        let b = r.u8(field)?;
        if k == 9 && b > 1 {
            return Err(r.corrupt(format!("{field} overflows")));
        }
        v |= ((b & 0x7f) as u64) << (7 * k);
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(r.corrupt(format!("{field} overflows")))
}

/// A Haar payload's pyramid levels and value-lattice step (for `vtz info`); checks only
/// those two fields.
pub fn describe(payload: &[u8]) -> Result<(usize, f64)> {
    let mut r = ByteReader::new(payload, "haar section");
    r.take(2, "coding and flags")?;
    let levels = r.u8("levels")? as usize;
    r.u8("bias")?;
    Ok((levels, r.finite_f64("lattice step")?))
}

/// Decode a Haar-section payload (invalid samples get the nodata fill).
pub fn decode(payload: &[u8], header: &Header, mask: Option<&[bool]>) -> Result<Vec<f64>> {
    let mut r = ByteReader::new(payload, "haar section");
    let coding = r.u8("coding")?;
    if coding != CODING_PYRAMID {
        return Err(r.corrupt(format!("coding {coding} is not defined")));
    }
    if r.u8("flags")? != 0 {
        return Err(r.corrupt("reserved flags are not zero"));
    }
    let (w, h) = (header.width as usize, header.height as usize);
    let n = w * h;
    if mask.is_some_and(|m| m.len() != n) {
        return Err(r.corrupt("mask size does not match the raster"));
    }
    let levels = r.u8("levels")? as usize;
    if levels > max_levels(w, h) {
        return Err(r.corrupt(format!(
            "{levels} levels is more than a {w}x{h} raster allows ({})",
            max_levels(w, h)
        )));
    }
    let bias = r.u8("bias")?;
    let step = r.finite_f64("lattice step")?;
    if step <= 0.0 {
        return Err(r.corrupt("lattice step is not positive"));
    }
    let offset = r.finite_f64("lattice offset")?;
    let bound = r.finite_f64("max error")?;
    if bound < 0.0 {
        return Err(r.corrupt("max error is negative"));
    }
    let pyr = Pyramid::new(w, h, levels);
    let mut steps = Vec::with_capacity(pyr.bands.len());
    for _ in 0..pyr.bands.len() {
        let s = read_varint(&mut r, "band step")?;
        if !(STEP_UNIT..=MAX_STEP).contains(&s) {
            return Err(r.corrupt(format!("band step {s}/16 is out of range")));
        }
        steps.push(s);
    }
    let stream = r.take(r.remaining(), "coefficients")?;
    let mut q = vec![0i64; n];
    Decoder::new(stream)
        .and_then(|mut dec| {
            code_bands(&mut dec, &mut q, &pyr)?;
            dec.finish()
        })
        .map_err(|e| e.context("haar section"))?;
    reconstruct(&mut q, &pyr, &steps, bias);
    let lattice = Lattice {
        step,
        offset,
        out: Output::new(header.sample_type, header.mapping),
    };
    let fill = header.nodata.unwrap_or(f64::NAN);
    q.iter()
        .enumerate()
        .map(|(i, &c)| {
            if mask.is_none_or(|m| m[i]) {
                lattice.value(c).ok_or_else(|| {
                    Error::corrupt(format!(
                        "haar section: sample {i} decodes to a non-finite value"
                    ))
                })
            } else {
                Ok(fill)
            }
        })
        .collect()
}
