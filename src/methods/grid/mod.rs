//! The grid section: every sample as an integer code (lossless or uniformly quantized within
//! a bound), predicted from its neighbours (LOCO-I median edge detector), varint + DEFLATE.
//!
//! This is vtz's simplest representation: exact for lossless, and a hard max-error bound
//! for lossy (closed loop: the encoder checks every sample as the decoder reconstructs it).

mod method;
pub(crate) use method::Grid;

use crate::container::Header;
use crate::container::bytes::{ByteReader, PutLe};
use crate::entropy::{self, varint};
use crate::error::{Error, Result};
use crate::model::{Raster, SampleType, ValueMapping};
use crate::predict::med::{CONTEXTS, context, predict};
use crate::quant::height_of;

const CODING_INT: u8 = 0;
const CODING_F32: u8 = 1;
const CODING_F64: u8 = 2;
const PRED_NONE: u8 = 0;
const PRED_MED: u8 = 1;
/// Residuals as zig-zag varints, raw DEFLATE.
const ENTROPY_DEFLATE: u8 = 0;
/// Residuals range coded, one adaptive integer model per local-activity context.
const ENTROPY_RANGE: u8 = 1;

/// Largest |code| for integer coding: codes and their reconstruction stay exact in f64.
const MAX_CODE: f64 = (1u64 << 52) as f64;

/// Parameters of the grid representation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GridParams {
    /// Max absolute error in data units; 0 means lossless.
    pub max_error: f64,
}

/// Order-preserving map of f32 bits to integers (negative floats flipped).
fn f32_key(v: f32) -> i64 {
    let b = v.to_bits() as i32;
    (if b < 0 { b ^ i32::MAX } else { b }) as i64
}
fn f32_from_key(k: i64) -> Option<f32> {
    let b = i32::try_from(k).ok()?;
    Some(f32::from_bits(
        (if b < 0 { b ^ i32::MAX } else { b }) as u32,
    ))
}
fn f64_key(v: f64) -> i64 {
    let b = v.to_bits() as i64;
    if b < 0 { b ^ i64::MAX } else { b }
}
fn f64_from_key(k: i64) -> f64 {
    f64::from_bits((if k < 0 { k ^ i64::MAX } else { k }) as u64)
}

/// How a decoder turns a code into a sample value (the encoder uses the same function).
#[derive(Clone, Copy)]
struct Dequant {
    coding: u8,
    step: f64,
    offset: f64,
    f32_out: bool,
    /// An integer sample type and its value mapping: coding 0's values are rounded to it,
    /// as every method's are (spec/FORMAT.md, grid section).
    int_out: Option<(SampleType, ValueMapping)>,
}

impl Dequant {
    #[inline]
    fn value(&self, code: i64) -> Option<f64> {
        let v = match self.coding {
            CODING_INT => {
                let v = height_of(code, self.step, self.offset);
                match self.int_out {
                    Some((st, m)) if v.is_finite() => st.nearest_value(v, m),
                    _ if self.f32_out => v as f32 as f64,
                    _ => v,
                }
            }
            CODING_F32 => f32_from_key(code)? as f64,
            _ => f64_from_key(code),
        };
        v.is_finite().then_some(v)
    }
}

/// Try integer coding with `step`/`offset`: codes chosen so that every valid sample's
/// reconstruction is within `tol` of it (exact when `tol` is 0: for float samples the same
/// bits, so a −0 sample rules integer codes out). `None` when impossible.
fn int_codes(r: &Raster, dq: Dequant, tol: f64) -> Option<Vec<i64>> {
    let bits = tol == 0.0 && !r.sample_type.is_integer();
    // The physical values an integer source type can hold.
    let range = r.sample_type.int_range().map(|(a, b)| {
        let (x, y) = (r.mapping.to_value(a), r.mapping.to_value(b));
        (x.min(y), x.max(y))
    });
    let mut codes = vec![0i64; r.len()];
    for (i, &v) in r.data.iter().enumerate() {
        if !r.is_valid(i) {
            continue;
        }
        let q = ((v - dq.offset) / dq.step).round();
        if q.is_nan() || q.abs() > MAX_CODE {
            return None;
        }
        let q = q as i64;
        // Closed loop: take the first candidate whose reconstruction meets the bound and
        // that the source's type can hold (255 with a step of 13 must not decode as 260).
        let ok = [q, q - 1, q + 1].into_iter().find(|&c| {
            dq.value(c).is_some_and(|rv| {
                (if bits { rv.to_bits() == v.to_bits() } else { (rv - v).abs() <= tol })
                    && range.is_none_or(|(lo, hi)| rv >= lo && rv <= hi)
            })
        })?;
        codes[i] = ok;
    }
    Some(codes)
}

/// Encode a raster's samples as a grid-section payload. Returns the payload and the max
/// error it guarantees (0 for lossless).
/// `progress` gets the fraction done (the quantization, the coding pass, deflate).
pub(crate) fn encode(
    r: &Raster,
    params: &GridParams,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, f64)> {
    if !(params.max_error >= 0.0 && params.max_error.is_finite()) {
        return Err(Error::invalid(format!(
            "max error {} must be a finite number ≥ 0",
            params.max_error
        )));
    }
    let f32_out = r.sample_type == SampleType::F32;
    let e = params.max_error;
    let mut chosen: Option<(Dequant, Vec<i64>, f64)> = None;
    let try_int = |step: f64, offset: f64, tol: f64| -> Option<(Dequant, Vec<i64>, f64)> {
        if !(step.is_finite() && step != 0.0 && offset.is_finite()) {
            return None;
        }
        let dq = Dequant {
            coding: CODING_INT,
            step,
            offset,
            f32_out,
            int_out: r.sample_type.is_integer().then_some((r.sample_type, r.mapping)),
        };
        int_codes(r, dq, tol).map(|c| (dq, c, tol))
    };
    let m = r.mapping;
    if r.sample_type.is_integer() {
        // Work in the source's code space so reconstructions are codes again.
        let qstep = if e > 0.0 {
            (2.0 * (e / m.scale.abs()).floor() + 1.0).min(MAX_CODE)
        } else {
            1.0
        };
        if qstep > 1.0 {
            chosen = try_int(m.scale * qstep, m.offset, e);
        }
        if chosen.is_none() {
            chosen = try_int(m.scale, m.offset, 0.0);
        }
    } else {
        if e > 0.0 {
            let (lo, hi) = r.valid_range().unwrap_or((0.0, 0.0));
            // Leave room for rounding the reconstruction to f32 (or f64), so a sample half a
            // step from two levels still lands within the bound.
            let ulp = if f32_out {
                2f64.powi(-23)
            } else {
                2f64.powi(-52)
            };
            let margin = 4.0 * ulp * lo.abs().max(hi.abs());
            if e > 2.0 * margin {
                chosen = try_int(2.0 * (e - margin), lo, e);
            }
        }
        // Float data that holds integers (many DEMs do) codes losslessly as integers.
        if chosen.is_none() {
            chosen = try_int(1.0, 0.0, 0.0);
        }
        // Or integers from the smallest value (a constant raster: every code 0, where bit
        // keys would spend a first residual of ~30 bits).
        if chosen.is_none() && e == 0.0 {
            if let Some((lo, _)) = r.valid_range() {
                chosen = try_int(1.0, lo, 0.0);
            }
        }
    }
    let (dq, codes, bound) = match chosen {
        Some(c) => c,
        None if r.sample_type.is_integer() => {
            // Integer codes reach every value of an integer type: a sample they miss is not
            // one, and a decoder rejects bit keys that are not (spec/FORMAT.md).
            let bad = (0..r.len())
                .find(|&i| r.is_valid(i) && !r.sample_type.holds(r.data[i], r.mapping))
                .unwrap_or(0);
            return Err(Error::invalid(
                r.sample_type
                    .check_holds(&format!("sample {bad}'s value"), r.data[bad], r.mapping)
                    .err()
                    .unwrap_or_else(|| "the samples have no integer codes".to_string()),
            ));
        }
        None => {
            let (coding, codes): (u8, Vec<i64>) = match r.sample_type {
                SampleType::F64 => (CODING_F64, r.data.iter().map(|&v| f64_key(v)).collect()),
                _ => (
                    CODING_F32,
                    r.data.iter().map(|&v| f32_key(v as f32)).collect(),
                ),
            };
            // Lossless only if the samples are exactly representable (f32 sources are).
            if coding == CODING_F32
                && r.data
                    .iter()
                    .enumerate()
                    .any(|(i, &v)| r.is_valid(i) && v as f32 as f64 != v)
            {
                return encode_f64_keys(r);
            }
            (
                Dequant {
                    coding,
                    step: 0.0,
                    offset: 0.0,
                    f32_out,
                    int_out: None,
                },
                codes,
                0.0,
            )
        }
    };
    progress(0.2);
    Ok((write_payload(r, dq, codes, bound, progress), bound))
}

fn encode_f64_keys(r: &Raster) -> Result<(Vec<u8>, f64)> {
    let dq = Dequant {
        coding: CODING_F64,
        step: 0.0,
        offset: 0.0,
        f32_out: false,
        int_out: None,
    };
    let codes = r.data.iter().map(|&v| f64_key(v)).collect();
    Ok((write_payload(r, dq, codes, 0.0, &mut |_| {}), 0.0))
}

fn write_payload(
    r: &Raster,
    dq: Dequant,
    codes: Vec<i64>,
    bound: f64,
    progress: &mut dyn FnMut(f64),
) -> Vec<u8> {
    write_payload_as(r, dq, codes, bound, None, progress)
}

/// [`write_payload`] with the residual coding forced (`Some`) or the smaller one (`None`).
fn write_payload_as(
    r: &Raster,
    dq: Dequant,
    mut codes: Vec<i64>,
    bound: f64,
    force: Option<u8>,
    progress: &mut dyn FnMut(f64),
) -> Vec<u8> {
    use crate::entropy::range::{Encoder, IntModel};
    let w = r.width;
    let mut stream = Vec::with_capacity(r.len());
    let mut enc = Encoder::with_capacity(r.len() / 2);
    let mut models: Vec<IntModel> = (0..CONTEXTS).map(|_| IntModel::new()).collect();
    let mut valid: u64 = 0;
    for i in 0..codes.len() {
        let p = predict(&codes, w, i);
        if r.is_valid(i) {
            let res = codes[i].wrapping_sub(p);
            varint::put_i64(&mut stream, res);
            models[context(&codes, w, i)].encode(&mut enc, res);
            valid += 1;
        } else {
            // Invalid samples take their prediction, so the decoder can rebuild them.
            codes[i] = p;
        }
    }
    progress(0.6);
    let deflated = entropy::deflate(&stream);
    progress(0.95);
    let ranged = enc.finish();
    let use_range = match force {
        Some(k) => k == ENTROPY_RANGE,
        None => ranged.len() <= deflated.len(),
    };
    let (kind, body) = if use_range {
        (ENTROPY_RANGE, ranged)
    } else {
        (ENTROPY_DEFLATE, deflated)
    };
    let mut out = Vec::new();
    out.put_u8(dq.coding);
    out.put_u8(PRED_MED);
    out.put_u8(kind);
    out.put_u8(0);
    out.put_f64(dq.step);
    out.put_f64(dq.offset);
    out.put_f64(bound);
    out.put_u64(valid);
    out.extend_from_slice(&body);
    out
}

/// Where the residuals come from while decoding.
enum Residuals<'a> {
    Varints(varint::VarintReader<'a>),
    Range(
        crate::entropy::range::Decoder<'a>,
        Vec<crate::entropy::range::IntModel>,
    ),
}

/// Decode a grid-section payload into sample values (invalid samples get the nodata fill).
pub fn decode(payload: &[u8], header: &Header, mask: Option<&[bool]>) -> Result<Vec<f64>> {
    let mut r = ByteReader::new(payload, "grid section");
    let coding = r.u8("coding")?;
    if coding > CODING_F64 {
        return Err(r.corrupt(format!("coding {coding} is not defined")));
    }
    let pred = r.u8("predictor")?;
    if pred != PRED_NONE && pred != PRED_MED {
        return Err(r.corrupt(format!("predictor {pred} is not defined")));
    }
    let ent = r.u8("entropy coder")?;
    if ent > ENTROPY_RANGE {
        return Err(r.corrupt(format!("entropy coder {ent} is not defined")));
    }
    if r.u8("reserved")? != 0 {
        return Err(r.corrupt("reserved field is not zero"));
    }
    let step = r.finite_f64("step")?;
    let offset = r.finite_f64("offset")?;
    let bound = r.finite_f64("max error")?;
    if bound < 0.0 {
        return Err(r.corrupt("max error is negative"));
    }
    if coding == CODING_INT && step == 0.0 {
        return Err(r.corrupt("step is zero"));
    }
    let valid = r.u64("valid count")?;
    let w = header.width as usize;
    let n = header.samples() as usize;
    let mask_valid = mask.map_or(n, |m| m.iter().filter(|&&b| b).count());
    if valid != mask_valid as u64 {
        return Err(r.corrupt(format!("holds {valid} samples, the mask says {mask_valid}")));
    }
    let rest = r.take(r.remaining(), "residuals")?;
    let stream;
    let mut src = if ent == ENTROPY_DEFLATE {
        stream = entropy::inflate(rest, mask_valid.saturating_mul(10), "grid section")?;
        Residuals::Varints(varint::VarintReader::new(&stream, "grid section residuals"))
    } else {
        Residuals::Range(
            crate::entropy::range::Decoder::new(rest)?,
            (0..CONTEXTS)
                .map(|_| crate::entropy::range::IntModel::new())
                .collect(),
        )
    };
    let dq = Dequant {
        coding,
        step,
        offset,
        f32_out: header.sample_type == SampleType::F32,
        int_out: header.sample_type.is_integer().then_some((header.sample_type, header.mapping)),
    };
    let fill = header.nodata.unwrap_or(f64::NAN);
    if mask_valid == 0 {
        // No sample is coded (a tile of sea in a flat region, all nodata): the loop below
        // would predict every code from zeros (0) and give every sample the fill; the same
        // result without a prediction per sample (an overview of the 20000² mosaic spent
        // 12 % of its time here).
        match src {
            Residuals::Varints(vr) => vr.finish()?,
            Residuals::Range(dec, _) => dec.finish()?,
        }
        return Ok(vec![fill; n]);
    }
    let mut codes = vec![0i64; n];
    let mut out = vec![0f64; n];
    for i in 0..n {
        let p = if pred == PRED_MED {
            predict(&codes, w, i)
        } else {
            0
        };
        if mask.is_none_or(|m| m[i]) {
            let res = match &mut src {
                Residuals::Varints(vr) => vr.i64()?,
                Residuals::Range(dec, models) => models[context(&codes, w, i)].decode(dec)?,
            };
            let c = p.wrapping_add(res);
            codes[i] = c;
            let v = dq.value(c).ok_or_else(|| {
                Error::corrupt(format!(
                    "grid section: sample {i} decodes to a non-finite value"
                ))
            })?;
            // Bit keys are the samples' values as stored: in an integer file each must be
            // a value of its type (the encoder keys only such values).
            if coding != CODING_INT && header.sample_type.is_integer() {
                header
                    .sample_type
                    .check_holds(&format!("sample {i}'s value"), v, header.mapping)
                    .map_err(|m| Error::corrupt(format!("grid section: {m}")))?;
            }
            out[i] = v;
        } else {
            codes[i] = p;
            out[i] = fill;
        }
    }
    match src {
        Residuals::Varints(vr) => vr.finish()?,
        Residuals::Range(dec, _) => dec.finish()?,
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Raster;

    /// The header of an int16 raster `r` with its valid range.
    fn int16_header(r: &Raster, nodata: Option<f64>) -> crate::container::Header {
        crate::container::Header {
            width: r.width as u32,
            height: r.height as u32,
            sample_type: SampleType::I16,
            primary: 0,
            mapping: Default::default(),
            nodata,
            range: r.valid_range(),
            georef: None,
        }
    }

    /// Integer codes that are the values (step 1, offset 0).
    const INTEGER_CODES: Dequant = Dequant {
        coding: CODING_INT,
        step: 1.0,
        offset: 0.0,
        f32_out: false,
        int_out: None,
    };

    /// A section with no coded sample (a tile all in flat regions or nodata) decodes to the
    /// fill everywhere, reads its whole (empty) stream, and a range-coded stream with bytes
    /// left over is corrupt, as through the per-sample loop.
    #[test]
    fn a_section_with_no_coded_sample_decodes_to_the_fill() {
        let (w, h) = (19, 7);
        let r = Raster::from_values(w, h, vec![f64::NAN; w * h], None, SampleType::I16).unwrap();
        let header = int16_header(&r, Some(-32768.0));
        let dq = INTEGER_CODES;
        for kind in [ENTROPY_DEFLATE, ENTROPY_RANGE] {
            let payload = write_payload_as(&r, dq, vec![0; w * h], 0.0, Some(kind), &mut |_| {});
            let mask = vec![false; w * h];
            let back = decode(&payload, &header, Some(&mask)).unwrap();
            assert_eq!(back, vec![-32768.0; w * h]);
            if kind == ENTROPY_RANGE {
                let mut longer = payload.clone();
                longer.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
                assert!(decode(&longer, &header, Some(&mask)).is_err());
            }
        }
    }

    #[test]
    fn both_residual_codings_decode_to_the_same_samples() {
        let data: Vec<f64> = (0..37 * 23)
            .map(|i| ((i * 7919) % 1013) as f64 + if i % 11 == 0 { f64::NAN } else { 0.0 })
            .collect();
        let r = Raster::from_values(37, 23, data, None, SampleType::I16).unwrap();
        let header = int16_header(&r, None);
        let codes: Vec<i64> = r
            .data
            .iter()
            .map(|&v| if v.is_nan() { 0 } else { v as i64 })
            .collect();
        let dq = INTEGER_CODES;
        for kind in [ENTROPY_DEFLATE, ENTROPY_RANGE] {
            let payload = write_payload_as(&r, dq, codes.clone(), 0.0, Some(kind), &mut |_| {});
            assert_eq!(payload[2], kind);
            let back = decode(&payload, &header, r.mask.as_deref()).unwrap();
            for (i, &b) in back.iter().enumerate() {
                if r.is_valid(i) {
                    assert_eq!(b, r.data[i]);
                }
            }
            // Every truncation of the residual stream is an error.
            for cut in 48..payload.len() {
                assert!(
                    decode(&payload[..cut], &header, r.mask.as_deref()).is_err(),
                    "kind {kind} cut {cut}"
                );
            }
        }
    }
}
